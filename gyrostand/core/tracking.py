"""Online identification, bin by bin: the online counterparts of the identifiers.

Each online identifier of :mod:`~gyrostand.core.registry` gives, through
:meth:`~gyrostand.core.registry.Identifier.track`, an :class:`OnlineTrack`: ``update(y, T)``
with each closed bin (``y`` the mean drift, NaN = gap; ``T`` the temperature, degC),
``estimate()`` the current :class:`OnlineEstimate` of every model parameter with its
standard deviation, ``finish()`` at stop and ``result(samples)`` the estimate as a
:class:`~gyrostand.core.results.FitResult`. Units are the model's: ``markov.beta`` 1/s,
``temp.gamma`` drift unit per (s·degC), noise levels in the drift unit.

LKF (:class:`LkfTrack`): linearised at the options' point with the noise levels held
(``markov.sigma``, ``white.sigma``, ...). Whatever the options leave out is taken from a
*warm-up* fit of the first ``warmup`` observed bins (least squares for the point where the
model allows it and finds β > 0, else ML; the core's held-value estimate for the noise
levels), after which the filter starts at the first bin and catches up over the warm-up
bins, so its estimate still uses every bin. Until then its status is
``insufficient_data``.

LSQ (:class:`LsqTrack`): sufficient statistics updated per bin, solved per bin (a 3×3
system); while the regressors are collinear (e.g. the temperature has not moved yet) the
status is ``insufficient_data`` ("not yet identifiable").
"""

from __future__ import annotations

import functools
import logging
import math
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from scipy.special import gammaincinv

from ..errors import GyrostandError
from .data import Samples
from .lkf.band import band_warnings, calibrated_estimates
from .lkf.filter import OnlineLKF, held_names, held_values, lkf_layout, relin_fit
from .lkf.relin import RelinLKF
from .lsq.fit import OnlineLSQ, lsq
from .lsq.fit import solve as lsq_solve
from .model import Model
from .options import LkfOptions, LsqOptions
from .results import Estimate, FitResult

__all__ = ["OnlineEstimate", "OnlineTrack", "LkfPoint", "LkfTrack", "LsqTrack",
           "resolve_lkf_point"]

log = logging.getLogger(__name__)

#: the LKF warm-up gives up after this many times ``warmup`` bins (bounded memory)
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


class OnlineTrack(Protocol):
    """The one interface of an online identifier (see the module docstring)."""

    def update(self, y: float, T: float) -> None: ...

    def estimate(self) -> OnlineEstimate: ...

    def finish(self) -> None: ...


@dataclass(frozen=True)
class LkfPoint:
    """A resolved LKF setting: linearisation point and held values (``held`` has every
    name of :func:`~gyrostand.core.lkf.filter.held_names`); ``source`` says where they came from."""

    beta0: float
    gamma0: float
    b0: float
    held: Mapping[str, float]
    source: str = "config"


def resolve_lkf_point(model: Model, cfg: LkfOptions, samples: Samples | None) -> LkfPoint:
    """Fill what ``cfg`` leaves out from a fit of ``samples`` (the warm-up, or the whole
    record in the final fit): least squares, or ML where LSQ cannot represent the model or
    finds no mean reversion (β ≤ 0). Raises :class:`GyrostandError` when the data cannot give it
    (too few bins, collinear regressors, a non-positive β)."""
    given = cfg.given
    point = {"markov.beta": cfg.beta0, "temp.gamma": cfg.gamma0, "bias.b": cfg.b0}
    need_point = [k for k, v in point.items() if v is None and
                  (k == "markov.beta" or k.split(".")[0] in model)]
    for k, v in model.defaults.items():  # a shape parameter not given: its default
        given.setdefault(k, v)
    need_held = [n for n in held_names(model) if n not in given]
    source = "config"
    if need_point or need_held:
        if samples is None:
            raise GyrostandError("lkf: no data yet for the warm-up fit")
        if need_point:
            from .ml.fit import ml  # (numba: only when a warm-up needs it)

            try:
                fit = lsq(samples, model)
                if not fit.value("markov.beta") > 0:  # no mean reversion seen by lsq
                    raise GyrostandError("lsq beta <= 0")
            except GyrostandError:
                fit = ml(samples, model, std_errors=False)
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


#: window of the online consistency check: mean normalised innovation e²/f over the last
#: this many observed bins (s at Δt = 1 s), tested against its χ² band
NIS_WINDOW = 300
#: two-sided probability outside which the window's mean e²/f is a warning
NIS_ALPHA = 1e-3
#: mean e²/f beyond which the filter is ``failed`` (its band means nothing)
NIS_FAIL = 10.0
#: a re-linearisation that moved a coefficient by more than this many stds: still moving
STEP_WARN_SIGMA = 3.0
#: default re-linearisation period, s of bins
RELINEARIZE_S = 100.0


@functools.lru_cache(maxsize=NIS_WINDOW + 1)
def _nis_band(n: int) -> tuple[float, float]:
    """Two-sided ``NIS_ALPHA`` band of the mean of ``n`` χ²(1) variables: the χ²(n)
    quantile is 2·P⁻¹(n/2, q), P⁻¹ the inverse regularized lower incomplete gamma."""
    return (2 * float(gammaincinv(n / 2, NIS_ALPHA / 2)) / n,
            2 * float(gammaincinv(n / 2, 1 - NIS_ALPHA / 2)) / n)


@dataclass
class LkfTrack:
    """The online LKF of one gyro: warm-up, then the configured variant bin by bin.

    ``relin`` (default): :class:`~gyrostand.core.lkf.relin.RelinLKF`, re-linearised every
    ``lkf.relinearize_every`` bins (default 100 s of bins), then every tenth of the record
    (:mod:`~gyrostand.core.lkf.schedule`), held noise levels not given in
    the session file re-estimated at each re-linearisation. ``paper``: the paper's single
    pass (:class:`~gyrostand.core.lkf.filter.OnlineLKF`) at the warm-up point.

    Status (:meth:`estimate`): ``failed`` when the filter's innovations are grossly
    inconsistent (mean e²/f over the last ``NIS_WINDOW`` bins > ``NIS_FAIL``) or not finite;
    ``warning`` when β ≤ 0, when β's ±3σ band contains 0 (not identified yet), when β sits
    at a bound, when that mean is outside its χ² band (probability ``NIS_ALPHA``), when the
    last re-linearisation moved a coefficient by more than ``STEP_WARN_SIGMA`` stds (still
    moving), when any coefficient's band is not calibrated yet
    (:func:`~gyrostand.core.lkf.band.band_warnings`: the point not settled, a coefficient
    not identified, off its linearisation point, or b = c/β with β too uncertain; each names
    its coefficient), and for the paper variant always (its estimate is one linearisation
    step, its band is not a confidence band); else ``ok``.
    """

    model: Model
    cfg: LkfOptions
    dt: float
    filter: OnlineLKF | RelinLKF | None = None
    point: LkfPoint | None = None
    buffered: list[tuple[float, float]] = field(default_factory=list)
    observed: int = 0
    next_try: int = 0
    e2: float = 0.0
    n_e: int = 0
    failed: str = ""
    #: e²/f of the last ``NIS_WINDOW`` observed bins, and their running sum
    nis: deque[float] = field(default_factory=lambda: deque(maxlen=NIS_WINDOW))
    nis_sum: float = 0.0

    def __post_init__(self) -> None:
        lkf_layout(self.model)  # raises ModelError for terms the LKF cannot represent
        self.next_try = self.cfg.warmup
        if not self.cfg.needs_warmup:
            self._start(resolve_lkf_point(self.model, self.cfg, None))

    @property
    def relinearize_every(self) -> int:
        every = self.cfg.relinearize_every
        return int(every) if every is not None else max(1, int(round(RELINEARIZE_S / self.dt)))

    def _start(self, point: LkfPoint) -> None:
        self.point = point
        if self.cfg.variant == "paper":
            self.filter = OnlineLKF(self.model, self.dt, beta0=point.beta0,
                                    gamma0=point.gamma0, b0=point.b0, held=point.held)
            log.warning("lkf.variant paper: the paper's single pass at a fixed point; its "
                        "estimate is one linearisation step and its std no confidence band "
                        "(status: warning); variant relin converges")
        else:
            fixed = tuple(self.cfg.held) + tuple(
                k for k, v in (("markov.sigma", self.cfg.sigma),
                               ("white.sigma", self.cfg.white_sigma)) if v is not None)
            self.filter = RelinLKF(
                self.model, self.dt, held=point.held, fixed=fixed, soaked=self.cfg.soaked,
                relinearize_every=self.relinearize_every,
                point={"markov.beta": point.beta0, "temp.gamma": point.gamma0,
                       "bias.b": point.b0})
        log.info("lkf (%s) started: beta0=%.4g gamma0=%.4g b0=%.4g held %s (%s)",
                 self.cfg.variant, point.beta0, point.gamma0, point.b0, dict(point.held),
                 point.source)
        pending, self.buffered = self.buffered, []
        for y, T in pending:
            self._feed(y, T)

    def _feed(self, y: float, T: float) -> None:
        f = self.filter
        assert f is not None
        if isinstance(f, RelinLKF):
            n0 = f.n
            relins = f.relinearizations
            f.update(y, T)
            if f.n == n0:
                return  # the bin waits for its centred rate (a rate term's lag)
            if f.relinearizations != relins or f.n > n0 + 1:
                # the history was re-filtered, or the first window of a rate term's bins
                # went through at once: the innovations anew
                self._refresh_nis()
                return
            e, v = f.last_innovation
        else:
            e, v = f.update(y, T)
        if math.isfinite(e):
            self.e2 += e * e
            self.n_e += 1
            if len(self.nis) == NIS_WINDOW:
                self.nis_sum -= self.nis[0]
            self.nis.append(e * e / v)
            self.nis_sum += e * e / v

    def finish(self) -> None:
        """At stop: a last re-linearisation over the whole record (relin variant), so the
        online estimate at stop is the filter's fixed point on every bin."""
        f = self.filter
        if isinstance(f, RelinLKF):
            f.flush()  # the bins still waiting for their centred rate
            if f.n > 0:
                f.relinearize()
                self._refresh_nis()

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
        if isinstance(self.filter, RelinLKF) and self.filter.n:
            self.filter.relinearize()  # at once on the warm-up bins
            self._refresh_nis()

    def _refresh_nis(self) -> None:
        """Innovation statistics after the history was re-filtered."""
        f = self.filter
        if isinstance(f, RelinLKF):
            e_all, v_all = f.innovations
            ok = np.isfinite(e_all)
            self.nis = deque((e_all[ok] ** 2 / v_all[ok])[-NIS_WINDOW:].tolist(),
                             maxlen=NIS_WINDOW)
            self.nis_sum = math.fsum(self.nis)
            self.e2, self.n_e = float(np.sum(e_all[ok] ** 2)), int(np.sum(ok))

    def status(self, est: Mapping[str, tuple[float, float]]) -> tuple[str, str]:
        """``(status, reason)`` of the current estimate (see the class docstring)."""
        f = self.filter
        assert f is not None
        fail: list[str] = []
        warn: list[str] = []
        if not all(math.isfinite(v) and math.isfinite(s) for v, s in est.values()):
            fail.append("non-finite estimate")
        nw = len(self.nis)
        if nw >= 30:
            m = self.nis_sum / nw
            lo, hi = _nis_band(nw)
            if m > NIS_FAIL:
                fail.append(f"innovations inconsistent: mean e²/f = {m:.3g} over the last "
                            f"{nw} bins (expected 1)")
            elif not lo <= m <= hi:
                warn.append(f"innovations inconsistent: mean e²/f = {m:.3g} over the last "
                            f"{nw} bins, outside [{lo:.2f}, {hi:.2f}]")
        b, sb = est["markov.beta"]
        if not b > 0:
            warn.append(f"beta = {b:.3g} <= 0 (not mean-reverting)")
        elif b - 3 * sb <= 0:
            warn.append(f"beta not identified yet: its ±3σ band [{b - 3 * sb:.3g}, "
                        f"{b + 3 * sb:.3g}] contains 0")
        if isinstance(f, RelinLKF):
            if b >= 0.99 * f.beta_max:
                warn.append(f"beta = {b:.3g} at its bound 1/dt")
            last = f.last
            if last is not None and last.settled:
                if last.noise_at_bound:
                    warn.append("a noise level reached a bound of its search (e.g. σ_v/σ "
                                "outside [1e-3, 1e2]): the band may be too narrow")
                elif last.step_sigma > STEP_WARN_SIGMA:
                    warn.append(f"estimate still moving: the last re-linearisation (bin "
                                f"{last.bins}) moved it by {last.step_sigma:.1f} std")
            warn += band_warnings(f)
        else:
            warn.append("paper variant: one linearisation step at the warm-up point; its "
                        "std is not a confidence band")
            lin = {"markov.beta": f.beta0, "temp.gamma": f.gamma0}
            at = [k for k, v0 in lin.items() if k in est and
                  abs(est[k][0] - v0) <= 1e-3 * max(abs(v0), 1e-12)]
            if at:
                warn.append(f"paper variant: {', '.join(at)} still at the linearisation point")
        if fail:
            return "failed", "; ".join(fail + warn)
        if warn:
            return "warning", "; ".join(warn)
        return "ok", ""

    def estimate(self) -> OnlineEstimate:
        names = self.model.param_names
        if self.filter is None or (self.filter.n if isinstance(self.filter, RelinLKF)
                                   else self.filter.k) == 0:
            note = self.failed or f"warm-up: {self.observed} of {self.cfg.warmup} bins"
            return OnlineEstimate("lkf", "failed" if self.failed else "insufficient_data",
                                  {n: (NAN, NAN) for n in names}, self.observed, NAN, note)
        est = (calibrated_estimates(self.filter) if isinstance(self.filter, RelinLKF)
               else self.filter.estimates)
        assert self.point is not None
        held = self.filter.held if isinstance(self.filter, RelinLKF) else self.point.held
        vals = {n: est[n] if n in est else (held.get(n, NAN), 0.0) for n in names}
        status, note = self.status(est)
        rms = math.sqrt(self.e2 / self.n_e) if self.n_e else NAN
        return OnlineEstimate("lkf", status, vals, self.observed, rms, note)

    def result(self, samples: Samples) -> FitResult:
        """The filter's current state as a :class:`FitResult` (``method`` "lkf",
        ``info["online"]`` true, its status and note), over ``samples`` (the gyro's
        ``samples.csv``: the filter's bins are its last ones). Raises
        :class:`GyrostandError` while it has no estimate."""
        e = self.estimate()
        f = self.filter
        if f is None or e.status == "insufficient_data":
            raise GyrostandError(f"the online lkf has no estimate: {e.note}")
        warnings = [f"lkf (online): {e.status}: {e.note}"] if e.note else []
        info = {"online": True, "status": e.status, "note": e.note,
                "point_from": self.point.source if self.point else ""}
        if isinstance(f, RelinLKF):
            first = max(len(samples) - f.n - f.pending, 0)
            return relin_fit(f, samples, warnings, info, first,
                             stds={n: v[1] for n, v in calibrated_estimates(f).items()})
        est = f.estimates
        model = self.model
        params = {n: (Estimate(est[n][0], est[n][1], model.unit(n)) if n in est else
                      Estimate(f.held[n], 0.0, model.unit(n), fixed=True))
                  for n in model.param_names}
        return FitResult(method="lkf", model=model, parameters=params, loglik=None,
                         residuals=np.full(len(samples), NAN), residual_var=None,
                         warnings=tuple(warnings), source=samples.source,
                         n_samples=len(samples), n_observed=samples.n_observed,
                         dt=samples.dt, info={**info, "variant": "paper",
                                              "linearization": {"markov.beta": f.beta0,
                                                                "temp.gamma": f.gamma0}})


@dataclass
class LsqTrack:
    """Online least squares of one gyro: the statistics updated per bin, solved on demand
    (:meth:`estimate`); equal to the batch :func:`~gyrostand.core.lsq.fit.lsq` on the same bins
    to rounding."""

    model: Model
    dt: float
    options: LsqOptions = field(default_factory=LsqOptions)
    lsq: OnlineLSQ = field(init=False)

    def __post_init__(self) -> None:
        self.lsq = OnlineLSQ(self.model, self.dt, regressor=self.options.regressor,
                             sigma=self.options.sigma)

    def update(self, y: float, T: float) -> None:
        self.lsq.update(y, T)

    def finish(self) -> None:
        """Nothing to do at stop: every estimate is already the solution on every bin."""

    def estimate(self) -> OnlineEstimate:
        names = self.model.param_names
        n = self.lsq.stats.n
        if not self.lsq.ready:
            return OnlineEstimate("lsq", "insufficient_data", {k: (NAN, NAN) for k in names},
                                  n, NAN, "too few bins")
        warnings: list[str] = []
        try:
            params, _, _, s2 = lsq_solve(self.lsq.stats, self.model, self.dt,
                                         self.options.sigma, warnings)
        except GyrostandError as exc:
            return OnlineEstimate("lsq", "insufficient_data", {k: (NAN, NAN) for k in names},
                                  n, NAN, f"not yet identifiable: {exc}")
        vals = {k: (params[k].value, params[k].std) for k in names}
        return OnlineEstimate("lsq", "warning" if warnings else "ok", vals, n,
                              math.sqrt(max(s2, 0.0)), "; ".join(warnings))

