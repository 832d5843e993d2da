"""The glue of the receive path, shared by live runs and replay: the listener's sample FIFO
drained into the binner. Live, the daemon calls :meth:`Ingest.pump` from its own thread
(never from the Notifier's); in replay, :func:`gyrostand.can.replay.replay` calls it between
frames. Same objects, same order of operations, so the same frames give the same bins.
"""

from __future__ import annotations

from dataclasses import dataclass

from gyrostand.can.binning import Bin, Binner
from gyrostand.can.receive.listener import DecodingListener

__all__ = ["Ingest"]


@dataclass
class Ingest:
    listener: DecodingListener
    binner: Binner

    def pump(self, max_items: int | None = None) -> list[Bin]:
        """Move decoded samples into the binner; return the bins that closed."""
        if max_items is None:  # the array path's samples stay arrays (the same bins)
            samples, chunks = self.listener.drain_chunks()
            bins = self.binner.add_many(samples) if samples else []
            for g, c, t, v in chunks:
                bins += self.binner.add_arrays(g, c, t, v)
            return bins
        return self.binner.add_many(self.listener.drain(max_items))

    def finish(self, until_t: float | None = None) -> list[Bin]:
        """End of run (or a timeout at frame time ``until_t``): settle the frames the
        listener holds (:meth:`~gyrostand.can.receive.listener.DecodingListener.settle`), pump,
        then flush."""
        if until_t is None:
            self.listener.settle()
        bins = self.pump()
        bins += self.binner.flush(until_t)
        return bins
