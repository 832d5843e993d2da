"""Online identification of one gyro, updated at every closed bin.

:class:`GyroTracker` holds the online identifiers a gyro's config asks for (``lkf``,
``lsq``; ``ml`` is batch-only and runs in the final fit) and gives, after every bin, each
identifier's current estimate of every model parameter with its standard deviation
(:class:`OnlineEstimate`). Units are the model's: ``markov.beta`` 1/s, ``temp.gamma`` drift
unit per (s·degC), noise levels in the drift unit (deg/h with our DBC).

LKF (:class:`~gyrostand.core.lkf.OnlineLKF`): linearised at the session's ``lkf`` point with
the noise levels held (``markov.sigma``, ``white.sigma``, ...). Whatever the config leaves
out is taken from a *warm-up* fit of the first ``lkf.warmup`` observed bins (least squares
for the point where the model allows it and finds β > 0, else ML; the core's held-value
estimate for the noise levels), after which the filter starts at the first bin and catches
up over the warm-up bins, so its estimate still uses every bin. Until then its status is
``insufficient_data``.

LSQ (:class:`~gyrostand.core.lsq.OnlineLSQ`): sufficient statistics updated per bin, solved
per bin (a 3×3 system); while the regressors are collinear (e.g. the temperature has not
moved yet) the status is ``insufficient_data`` ("not yet identifiable").

A bin whose drift channel is empty is a gap (the filters predict over it); a bin whose
temperature channel is empty uses the last temperature seen (the batch fit interpolates).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from ..config import GyroConfig, LkfConfig
from ..core.data import Samples
from ..core.identify import identify
from ..core.lkf import OnlineLKF, held_names, held_values, lkf_layout
from ..core.lsq import OnlineLSQ
from ..core.lsq import solve as lsq_solve
from ..core.model import Model
from ..errors import GyrostandError

__all__ = ["OnlineEstimate", "GyroTracker", "LkfPoint", "resolve_lkf_point", "ONLINE"]

log = logging.getLogger(__name__)

#: identifiers that run online (per bin); the others only in the final fit
ONLINE = ("lkf", "lsq")
#: the LKF warm-up gives up after this many times ``lkf.warmup`` bins (bounded memory)
MAX_WARMUP_FACTOR = 20
NAN = math.nan


@dataclass(frozen=True)
class OnlineEstimate:
    """One identifier's current estimate: ``values[name] = (value, std)`` for every model
    parameter (NaN while unknown; std 0 for a held value), ``status`` one of ``ok``,
    ``warning``, ``insufficient_data``, ``failed``; ``samples`` bins used; ``residual_rms``
    RMS of the one-step residuals (drift unit; NaN while unknown); ``note`` why not ok."""

    identifier: str
    status: str
    values: Mapping[str, tuple[float, float]]
    samples: int = 0
    residual_rms: float = NAN
    note: str = ""


@dataclass(frozen=True)
class LkfPoint:
    """A resolved LKF setting: linearisation point and held values (``held`` has every
    name of :func:`~gyrostand.core.lkf.held_names`); ``source`` says where they came from."""

    beta0: float
    gamma0: float
    b0: float
    held: Mapping[str, float]
    source: str = "config"


def resolve_lkf_point(model: Model, cfg: LkfConfig, samples: Samples | None) -> LkfPoint:
    """Fill what ``cfg`` leaves out from a fit of ``samples`` (the warm-up, or the whole
    record in the final fit): least squares, or ML where LSQ cannot represent the model or
    finds no mean reversion (β ≤ 0). Raises :class:`GyrostandError` when the data cannot give it
    (too few bins, collinear regressors, a non-positive β)."""
    given: dict[str, float] = dict(cfg.held)
    if cfg.sigma is not None:
        given["markov.sigma"] = cfg.sigma
    if cfg.white_sigma is not None:
        given["white.sigma"] = cfg.white_sigma
    point = {"markov.beta": cfg.beta0, "temp.gamma": cfg.gamma0, "bias.b": cfg.b0}
    need_point = [k for k, v in point.items() if v is None and
                  (k == "markov.beta" or k.split(".")[0] in model)]
    need_held = [n for n in held_names(model) if n not in given]
    source = "config"
    if need_point or need_held:
        if samples is None:
            raise GyrostandError("lkf: no data yet for the warm-up fit")
        if need_point:
            try:
                fit = identify(samples, model, "lsq")
                if not fit.value("markov.beta") > 0:  # no mean reversion seen by lsq
                    raise GyrostandError("lsq beta <= 0")
            except GyrostandError:
                fit = identify(samples, model, "ml", std_errors=False)
            for k in need_point:
                point[k] = fit.value(k)
            source = f"{fit.method} fit of {samples.n_observed} bins"
        if need_held:
            hv, src = held_values(samples, model, given)
            given.update(hv)
            source += f"; noise from {src}" if need_point else f"noise from {src}"
    beta0 = float(point["markov.beta"] or 0.0)
    if not beta0 > 0:
        raise GyrostandError(f"lkf: linearisation point beta0 = {beta0:.3g} is not > 0")
    held = {n: float(given[n]) for n in held_names(model)}
    if held.get("markov.sigma", 1.0) <= 0:
        raise GyrostandError("lkf: markov.sigma must be > 0")
    return LkfPoint(beta0, float(point["temp.gamma"] or 0.0), float(point["bias.b"] or 0.0),
                    held, source)


@dataclass
class _LkfTrack:
    model: Model
    cfg: LkfConfig
    dt: float
    filter: OnlineLKF | None = None
    point: LkfPoint | None = None
    buffered: list[tuple[float, float]] = field(default_factory=list)
    observed: int = 0
    next_try: int = 0
    e2: float = 0.0
    n_e: int = 0
    failed: str = ""

    def __post_init__(self) -> None:
        lkf_layout(self.model)  # raises ModelError for terms the LKF cannot represent
        self.next_try = self.cfg.warmup
        if not self.cfg.needs_warmup:
            self._start(resolve_lkf_point(self.model, self.cfg, None))

    def _start(self, point: LkfPoint) -> None:
        self.point = point
        self.filter = OnlineLKF(self.model, self.dt, beta0=point.beta0, gamma0=point.gamma0,
                                b0=point.b0, held=point.held)
        log.info("lkf started: beta0=%.4g gamma0=%.4g b0=%.4g held %s (%s)", point.beta0,
                 point.gamma0, point.b0, dict(point.held), point.source)
        pending, self.buffered = self.buffered, []
        for y, T in pending:
            self._feed(y, T)

    def _feed(self, y: float, T: float) -> None:
        assert self.filter is not None
        e, _ = self.filter.update(y, T)
        if math.isfinite(e):
            self.e2 += e * e
            self.n_e += 1

    def update(self, y: float, T: float) -> None:
        if not math.isnan(y):
            self.observed += 1
        if self.filter is not None:
            self._feed(y, T)
            return
        if self.failed:
            return
        self.buffered.append((y, T))
        if len(self.buffered) > MAX_WARMUP_FACTOR * self.cfg.warmup:
            self.failed = (f"no usable warm-up within {len(self.buffered)} bins; give "
                           "lkf.beta0, gamma0, b0, sigma, white_sigma in the session file")
            log.warning("lkf: %s", self.failed)
            self.buffered = []  # gave up (until a reset)
            return
        if self.observed < self.next_try:
            return
        self.next_try = self.observed + max(10, self.cfg.warmup // 5)
        ys = np.array([b[0] for b in self.buffered])
        Ts = np.array([b[1] for b in self.buffered])
        try:
            samples = Samples.from_arrays(self.dt * np.arange(ys.size), ys, Ts, dt=self.dt,
                                          source="lkf warm-up")
            point = resolve_lkf_point(self.model, self.cfg, samples)
        except GyrostandError as exc:
            log.info("lkf warm-up not yet possible (%s); retrying after %d more bins", exc,
                     self.next_try - self.observed)
            return
        self._start(point)

    def estimate(self) -> OnlineEstimate:
        names = self.model.param_names
        if self.filter is None or self.filter.k == 0:
            note = self.failed or f"warm-up: {self.observed} of {self.cfg.warmup} bins"
            return OnlineEstimate("lkf", "failed" if self.failed else "insufficient_data",
                                  {n: (NAN, NAN) for n in names}, self.observed, NAN, note)
        est = self.filter.estimates
        assert self.point is not None
        vals = {n: est[n] if n in est else (self.point.held.get(n, NAN), 0.0) for n in names}
        status = "ok"
        note = ""
        if est["markov.beta"][0] <= 0:
            status, note = "warning", "beta <= 0"
        rms = math.sqrt(self.e2 / self.n_e) if self.n_e else NAN
        return OnlineEstimate("lkf", status, vals, self.observed, rms, note)


@dataclass
class _LsqTrack:
    model: Model
    dt: float
    lsq: OnlineLSQ = field(init=False)

    def __post_init__(self) -> None:
        self.lsq = OnlineLSQ(self.model, self.dt)

    def update(self, y: float, T: float) -> None:
        self.lsq.update(y, T)

    def estimate(self) -> OnlineEstimate:
        names = self.model.param_names
        n = self.lsq.stats.n
        if not self.lsq.ready:
            return OnlineEstimate("lsq", "insufficient_data", {k: (NAN, NAN) for k in names},
                                  n, NAN, "too few bins")
        warnings: list[str] = []
        try:
            params, _, _, s2 = lsq_solve(self.lsq.stats, self.model, self.dt, None, warnings)
        except GyrostandError as exc:
            return OnlineEstimate("lsq", "insufficient_data", {k: (NAN, NAN) for k in names},
                                  n, NAN, f"not yet identifiable: {exc}")
        vals = {k: (params[k].value, params[k].std) for k in names}
        return OnlineEstimate("lsq", "warning" if warnings else "ok", vals, n,
                              math.sqrt(max(s2, 0.0)), "; ".join(warnings))


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
        self._tracks: dict[str, _LkfTrack | _LsqTrack] = {}
        self._failed: dict[str, str] = {}
        for ident in self.identifiers:
            try:
                if ident == "lkf":
                    self._tracks[ident] = _LkfTrack(self.model, self.gyro.lkf, self.dt)
                else:
                    self._tracks[ident] = _LsqTrack(self.model, self.dt)
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

    @property
    def lkf_point(self) -> LkfPoint | None:
        t = self._tracks.get("lkf")
        return t.point if isinstance(t, _LkfTrack) else None

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
