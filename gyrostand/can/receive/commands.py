"""Command frames: decoded whole by cantools into a bounded queue, whatever their time.

A frame of the session's command message is never subject to the data channels' time
checks; its timestamp is only used to rate-limit commands. A frame of the command id that
cannot be a command is queued marked :data:`MALFORMED` so the daemon answers it with a
nack (:mod:`gyrostand.session.commands`).
"""

from __future__ import annotations

import math

from gyrostand.can.receive.counts import REASONS
from gyrostand.can.receive.state import ReceiveState
from gyrostand.can.routes import Route

__all__ = ["CommandQueue", "Command", "MALFORMED"]

#: a queued command: (timestamp s, {signal: value})
Command = tuple[float, dict[str, float]]
#: key of a queued command frame that could not be decoded (value: index in REASONS)
MALFORMED = "__malformed__"

_isfinite = math.isfinite


class CommandQueue(ReceiveState):
    """The command queue: filled by the receive path (the caller holds the lock), read
    with :meth:`pop_commands`."""

    def _command(self, route: Route, t: float, data: bytes | bytearray) -> None:
        """Queue a command frame (decoded; a payload that cannot be decoded is queued
        ``MALFORMED``). Its timestamp is only used to rate-limit commands (a timestamp
        that is not finite becomes the newest frame time)."""
        rej, n = self._rej, self._n
        try:
            values = route.decode(data)
        except Exception:
            rej.undecodable += 1
            self._malformed_command(route, t, data, "undecodable")
            return
        if len(self._commands) >= self._command_capacity:
            rej.command_overflow += 1  # not the samples' overflow: the command queue's
            return
        self._commands.append((t if _isfinite(t) else self.last_timestamp, dict(values)))
        n.decoded += 1
        n.commands += 1

    def _malformed_command(self, route: Route, t: float, data: bytes | bytearray,
                           why: str) -> None:
        """A frame of the command id that cannot be a command (already counted as
        rejected): queue it marked ``MALFORMED`` so the daemon answers with a nack, with
        whatever signals the bytes present still give (to echo Command and Sequence)."""
        if len(self._commands) >= self._command_capacity:
            return  # counted already (wrong_dlc / undecodable); no room for its nack
        try:
            values = dict(route.message.decode(bytes(data), decode_choices=False,
                                               allow_truncated=True, allow_excess=True))
        except Exception:
            values = {}
        values[MALFORMED] = float(REASONS.index(why))
        self._commands.append((t if _isfinite(t) else self.last_timestamp, values))

    def pop_commands(self) -> list[Command]:
        """Decoded command frames ``(timestamp, {signal: value})`` received so far."""
        out = []
        while self._commands:
            out.append(self._commands.popleft())
        return out
