"""Online identification of one gyro, updated at every closed bin.

:class:`GyroTracker` holds the online identifiers a gyro's config asks for (those of the
registry, :mod:`gyrostand.core.registry`, that run online: ``lkf``, ``lsq``; ``ml`` is
batch-only and runs in the final fit) and gives, after every bin, each identifier's current
estimate of every model parameter with its standard deviation (:class:`OnlineEstimate`).
Each runs behind one interface (:class:`~gyrostand.core.tracking.OnlineTrack`:
``update``/``estimate``/``finish``); their numerics and status rules are in
:mod:`gyrostand.core.tracking`, with their options from the session file
(:meth:`~gyrostand.config.GyroConfig.options`: the ``lkf:`` section for the LKF).

A bin whose drift channel is empty is a gap (the filters predict over it); a bin whose
temperature channel is empty uses the last temperature seen (the batch fit interpolates).
"""

from __future__ import annotations

import logging
import math

from ..config import GyroConfig
from ..core.data import Samples
from ..core.model import Model
from ..core.registry import REGISTRY
from ..core.results import FitResult
from ..core.tracking import (
    LkfPoint,
    LkfTrack,
    LsqTrack,
    OnlineEstimate,
    OnlineTrack,
    resolve_lkf_point,
)
from ..errors import GyrostandError

__all__ = ["OnlineEstimate", "GyroTracker", "LkfPoint", "LkfTrack", "LsqTrack",
           "resolve_lkf_point", "ONLINE"]

log = logging.getLogger(__name__)

#: identifiers that run online (per bin); the others only in the final fit
ONLINE = tuple(name for name, ident in REGISTRY.items() if ident.online)
NAN = math.nan


class GyroTracker:
    """The online identifiers of one gyro (those of ``gyro.identifiers`` that run online).

    An identifier that cannot represent the gyro's model (e.g. ``lsq`` with ``markov2``)
    is reported with status ``failed`` and the reason, and never updated.
    """

    def __init__(self, gyro: GyroConfig, dt: float) -> None:
        self.gyro = gyro
        self.dt = float(dt)
        self.model = Model.parse(gyro.model)
        self.identifiers = tuple(i for i in gyro.identifiers if i in ONLINE)
        self.reset()

    def reset(self) -> None:
        """Forget every online estimate; identification restarts at the next bin."""
        self._tracks: dict[str, OnlineTrack] = {}
        self._failed: dict[str, str] = {}
        for ident in self.identifiers:
            try:
                self._tracks[ident] = REGISTRY[ident].track(self.model, self.dt,
                                                            self.gyro.options(ident))
            except GyrostandError as exc:
                self._failed[ident] = str(exc)
                log.warning("gyro %s: online %s unavailable: %s", self.gyro.name, ident, exc)
        self._last_T = NAN
        self.bins = 0
        self._cached: list[OnlineEstimate] | None = None

    def update(self, drift: float, temp: float) -> None:
        """One closed bin: mean drift (NaN = gap) and mean temperature (degC, NaN = none)."""
        self.bins += 1
        self._cached = None
        if math.isnan(temp):
            temp = self._last_T
        else:
            self._last_T = temp
        if math.isnan(temp):  # no temperature yet: nothing to identify with
            return
        for ident, track in list(self._tracks.items()):
            try:
                track.update(drift, temp)
            except Exception as exc:  # an identifier's failure must not stop the daemon
                log.exception("gyro %s: online %s failed at bin %d; disabled until reset",
                              self.gyro.name, ident, self.bins)
                del self._tracks[ident]
                self._failed[ident] = f"failed at bin {self.bins}: {exc}"

    def finish(self) -> None:
        """At stop: each online identifier's last step (the LKF's last re-linearisation
        over the whole record, so its estimate at stop, ``lkf`` in every output, is its
        fixed point on every bin)."""
        for ident, track in self._tracks.items():
            try:
                track.finish()
            except Exception:  # the final fit still runs; the online value stays as it was
                log.exception("gyro %s: the online %s's last step at stop failed",
                              self.gyro.name, ident)
        self._cached = None

    def online_fit(self, identifier: str, samples: Samples) -> FitResult:
        """The online ``identifier``'s current state as a :class:`FitResult` (``info["online"]``
        true, its status and note), over ``samples`` (the gyro's ``samples.csv``: the
        filter's bins are its last ones); for the identifiers that report it
        (``reports_online``, the LKF). Raises :class:`GyrostandError` while it has none."""
        t = self._tracks.get(identifier)
        result = getattr(t, "result", None)
        if result is None:
            raise GyrostandError(self._failed.get(
                identifier, f"the online {identifier} is not running"))
        return result(samples)

    def lkf_fit(self, samples: Samples) -> FitResult:
        """:meth:`online_fit` of the LKF (what the last CAN round sent)."""
        return self.online_fit("lkf", samples)

    @property
    def lkf_point(self) -> LkfPoint | None:
        t = self._tracks.get("lkf")
        return t.point if isinstance(t, LkfTrack) else None

    def estimates(self) -> list[OnlineEstimate]:
        """Current estimate of every online identifier, in config order (computed once
        per bin)."""
        if self._cached is not None:
            return self._cached
        out = []
        for ident in self.identifiers:
            if ident in self._failed:
                out.append(OnlineEstimate(ident, "failed",
                                          {n: (NAN, NAN) for n in self.model.param_names},
                                          0, NAN, self._failed[ident]))
            else:
                out.append(self._tracks[ident].estimate())
        self._cached = out
        return out
