"""The online LKF's re-linearisation schedule (issue 25, item 1): total re-filter work
linear in the record whatever the data, measured on a record whose point does not settle.
benchmarks/lkf_cost.py measures the cost on 24-h records."""

from gyrostand.core.lkf.relin import RelinLKF
from gyrostand.core.lkf.schedule import GROWTH, UNSETTLED_PASSES, RelinSchedule
from gyrostand.core.model import Model
from gyrostand.core.profiles import chamber_profile
from gyrostand.core.simulation import simulate

#: gyro x of configs/three-gyros.yaml, with a strong dT/dt and hysteresis effect that the
#: filter's model lacks: the point does not settle at several re-linearisations
TRUTH = {"markov.beta": 0.002, "markov.sigma": 0.05, "temp.gamma": -0.0001, "bias.b": 0.3,
         "white.sigma": 0.01, "temp_rate.k": 50.0, "hysteresis.h": 0.5}
MODEL = Model.parse("markov,temp,bias,white")


def _work(schedule: RelinSchedule, n_bins: int, passes: int, settled: bool):
    """(re-linearisations, passes, Σ passes × bins) of ``n_bins`` under ``schedule`` when
    every re-linearisation takes the passes it is allowed, up to ``passes``."""
    relins = total = work = 0
    for n in range(1, n_bins + 1):
        if schedule.is_due(n):
            p = schedule.max_passes(passes)
            schedule.record(n, p, settled)
            relins, total, work = relins + 1, total + p, work + p * n
    return relins, total, work


def test_schedule_work_is_linear_in_the_record_even_when_nothing_settles():
    n = 20_000
    for settled, passes in ((True, 2), (False, 30)):
        r1, p1, w1 = _work(RelinSchedule(100), n, passes, settled)
        r4, p4, w4 = _work(RelinSchedule(100), 4 * n, passes, settled)
        assert w4 <= 5 * w1, (settled, w1, w4)  # N²: 16x
        assert p4 <= 5 * p1 and r4 - r1 <= 16, (r1, r4)  # log(4)/log(1.1) = 14.5 more
        per_bin = (1 + 1 / GROWTH) * (passes if settled else UNSETTLED_PASSES)
        assert w4 / (4 * n) <= per_bin + 1, (settled, w4 / (4 * n))
    # unsettled: the first one keeps its passes and bin, the later ones are capped
    s = RelinSchedule(100)
    s.record(100, 31, False)
    s.record(200, 3, False)
    assert (s.unsettled_since, s.unsettled_passes, s.max_passes(30)) == (100, 31, 3)
    s.record(300, 2, True)
    assert s.unsettled_since is None and s.max_passes(30) == 30 and s.due == 400
    s.record(5000, 1, True)
    assert s.due == 5500


def test_passes_on_a_long_unsettled_record_grow_like_n_log_n_not_n_squared():
    n = 3000
    s = simulate(Model.parse("markov,temp,bias,white,temp_rate,hysteresis"), TRUTH,
                 chamber_profile(4 * n / 3600), seed=2)
    runs = {}
    for bins in (n, 4 * n):
        f = RelinLKF(MODEL, 1.0, point={"markov.beta": 0.002, "temp.gamma": -0.0001,
                                        "bias.b": 0.3},
                     held={"markov.sigma": 0.05, "white.sigma": 0.01}, relinearize_every=100)
        unsettled, last = 0, None
        for y, T in zip(s.drift[:bins].tolist(), s.temp[:bins].tolist(), strict=True):
            f.update(y, T)
            if f.last is not last:
                last = f.last
                unsettled += not last.settled
        runs[bins] = (f.total_passes, f.refiltered, unsettled, f.relinearizations)
    (p1, w1, _, _), (p4, w4, u4, r4) = runs[n], runs[4 * n]
    assert u4 >= 3, runs  # a record whose point does not settle
    # passes and work: N log N at most (every 100 bins: 4x the passes, 16x the work)
    assert p4 <= 5 * p1 and w4 <= 5 * w1, runs
    assert w4 <= 4 * n * (1 + 1 / GROWTH) * 30, runs  # work per bin bounded
    # every 100 bins as before: 120 re-linearisations over 12,000 bins, ≥ 7.2 M bin-passes
    assert r4 <= 40 and w4 < 1.5e6, runs
