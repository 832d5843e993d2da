"""What a design will realise (#24 item 7): the verify's gain with a bootstrap interval
as the headline; an expected-LR ratio over a reference below 1 never quoted as a gain."""

from __future__ import annotations

import numpy as np
import pytest

from gyrostand.core.design.realised import (
    bootstrap_ratio,
    expected_gain,
    gain_words,
    ratio,
    realised_lr_gain,
    realised_std_gain,
)


def test_an_expected_lr_below_one_carries_no_gain():
    # the trend vs warm-up protocol: 63 over 0.315 was quoted as "200x"; verify realised 42x
    assert expected_gain(63.0, 0.315) is None
    assert gain_words(63.0, 0.315) == "expected LR 63 vs 0.315"
    assert expected_gain(51.2, 9.49) == pytest.approx(5.395, abs=1e-3)
    assert gain_words(51.2, 9.49) == "gain 5.40x (expected LR 51.2 vs 9.49)"


def test_the_bootstrap_interval_holds_the_ratio_and_shrinks_with_more_runs():
    rng = np.random.default_rng(3)

    def mean(groups):
        return float(np.mean(groups[0]))

    small = bootstrap_ratio(mean, [rng.normal(20, 5, 20)], [rng.normal(10, 5, 20)])
    big = bootstrap_ratio(mean, [rng.normal(20, 5, 500)], [rng.normal(10, 5, 500)])
    for value, lo, hi in (small, big):
        assert lo < value < hi
    assert big[2] - big[1] < 0.5 * (small[2] - small[1])
    assert big[1] < 2.0 < big[2]  # the true ratio, 20/10
    same = bootstrap_ratio(mean, [np.full(5, 4.0)], [np.full(5, 2.0)])
    assert same == (2.0, 2.0, 2.0)


def test_the_separation_gain_is_the_ratio_of_the_summed_mean_lrs():
    v = {"runs": 4,
         "designed": {"a": {"lrs": [30.0, 20.0, 25.0, 27.0]}, "b": {"lrs": [5.0, 6.0, 4.0, 5.0]}},
         "reference": {"a": {"lrs": [10.0, 8.0, 9.0, 11.0]}, "b": {"lrs": [1.0, 0.5, 1.5, 1.0]}}}
    g = realised_lr_gain(v, ("a", "b"))
    assert g["ratio"] == pytest.approx((25.5 + 5.0) / (9.5 + 1.0))
    lo, hi = g["interval"]
    assert lo < g["ratio"] < hi and g["runs"] == 4 and g["level"] == 0.95
    assert realised_lr_gain({"runs": 1, "designed": {}, "reference": {}}, ("a", "b")) is None


def test_the_std_gain_is_the_worst_relative_std_reference_over_designed():
    rng = np.random.default_rng(5)
    params = {"k": 5.0, "h": 0.05}
    designed = {"k": list(rng.normal(5, 0.5, 30)), "h": list(rng.normal(0.05, 0.002, 30))}
    reference = {"k": list(rng.normal(5, 1.5, 30)), "h": list(rng.normal(0.05, 0.004, 30))}
    g = realised_std_gain(designed, reference, ("k", "h"), params)
    worst_d = max(np.std(designed["k"], ddof=1) / 5, np.std(designed["h"], ddof=1) / 0.05)
    worst_r = max(np.std(reference["k"], ddof=1) / 5, np.std(reference["h"], ddof=1) / 0.05)
    assert g["ratio"] == pytest.approx(worst_r / worst_d)
    assert g["interval"][0] < g["ratio"] < g["interval"][1]
    assert realised_std_gain({"k": [1.0]}, {"k": [1.0]}, ("k",), params) is None


def test_the_interval_is_seeded():
    rng = np.random.default_rng(9)
    a, b = [rng.normal(20, 5, 20)], [rng.normal(10, 5, 20)]

    def mean(groups):
        return float(np.mean(groups[0]))

    assert bootstrap_ratio(mean, a, b) == bootstrap_ratio(mean, a, b)
    assert bootstrap_ratio(mean, a, b, seed=1) != bootstrap_ratio(mean, a, b)


def test_design_json_names_the_units_of_its_numbers(tmp_path):
    """Units in every document (issue 27): design.json says the unit of each std."""
    import json

    from gyrostand.cli import main

    out = tmp_path / "d"
    assert main(["design", "--model", "markov,temp", "--param", "markov.beta=0.01",
                 "--param", "markov.sigma=0.05", "--param", "temp.gamma=-0.0005",
                 "--param", "white.sigma=0.02", "--hours", "2", "--evaluations", "2",
                 "--out", str(out), "-q"]) == 0
    units = json.loads((out / "design.json").read_text())["units"]
    assert units["parameters"] == {"markov.beta": "1/s", "markov.sigma": "y",
                                   "temp.gamma": "y/(s·°C)", "white.sigma": "y"}
    assert (units["time"], units["temperature"]) == ("s", "degC")


def test_a_resample_without_spread_does_not_stop_the_interval():
    # design --verify 4 crashed (ZeroDivisionError): a bootstrap resample of a few runs
    # can repeat one run, whose spread is 0. Its ratio is infinite, kept as an order
    # statistic; the point estimate stays the plain ratio.
    designed = {"k": [1.0, 1.1, 0.9]}
    reference = {"k": [1.0, 1.4, 0.6]}
    got = realised_std_gain(designed, reference, ["k"], {"k": 1.0})
    assert got["ratio"] == pytest.approx(np.std([1.0, 1.4, 0.6], ddof=1)
                                         / np.std([1.0, 1.1, 0.9], ddof=1))
    lo, hi = got["interval"]
    # 3 runs: 3 of 27 resamples repeat one run (1/9 > 2.5 % of the draws): the
    # reference's give ratio 0, the designed's inf -- with 3 runs nothing is excluded
    assert (lo, hi) == (0.0, np.inf)
    # 4 runs: 4 of 256 (1.6 %) -- both ends finite again
    got4 = realised_std_gain({"k": [1.0, 1.1, 0.9, 1.05]}, {"k": [1.0, 1.4, 0.6, 1.2]},
                             ["k"], {"k": 1.0})
    assert 0 < got4["interval"][0] < got4["ratio"] < got4["interval"][1] < np.inf
    assert ratio(0.0, 0.0) != ratio(0.0, 0.0)  # nan
    assert ratio(-1.0, 0.0) == -np.inf and ratio(3.0, 2.0) == 1.5


def test_verify_names_what_the_prediction_holds_and_shows_the_bulk_spread(tmp_path, capsys):
    """The predicted stds take a shape parameter at its plain value as known (temp_rate's
    lag 0); verify's fits estimate it, as a fit of the run will. design says so
    (``predicted_given``) and prints each realized spread twice: the std and the robust
    std of the bulk, so a tail of runs that traded k against the lag shows as such."""
    import json

    from gyrostand.cli import main
    from gyrostand.core.validate import robust_std

    assert robust_std([1.0, 2.0, 3.0, 4.0, 100.0]) == pytest.approx(1.4826)
    assert robust_std([5.0, 5.0, 5.0]) == 0.0
    out = tmp_path / "d"
    assert main(["design", "--model", "markov,temp,bias,temp_rate,white",
                 "--param", "markov.beta=0.0015", "--param", "markov.sigma=0.05",
                 "--param", "temp.gamma=-0.0002", "--param", "bias.b=0.1",
                 "--param", "temp_rate.k=5", "--param", "white.sigma=0.01",
                 "--hours", "2", "--evaluations", "2", "--verify", "3",
                 "--out", str(out), "-q"]) == 0
    text = capsys.readouterr().out
    doc = json.loads((out / "design.json").read_text())
    assert doc["predicted_given"] == {"temp_rate.tau": 0.0}
    assert "temp_rate.tau" not in doc["predicted_std"]
    for label in ("designed", "reference"):
        got = doc["verify"][label]
        assert set(got["realized_robust_std"]) == set(got["realized_std"])
        assert got["realized_robust_std"]["temp_rate.k"] > 0
    assert "predicted with temp_rate.tau = 0 known; verify's fits estimate it" in text
    k = next(ln for ln in text.splitlines() if ln.strip().startswith("temp_rate.k ")
             and "designed" in ln)
    d = doc["verify"]["designed"]
    pred = doc["predicted_std"]["temp_rate.k"]
    assert (f"({d['realized_std']['temp_rate.k'] / pred:.2f}; "
            f"{d['realized_robust_std']['temp_rate.k'] / pred:.2f})") in k
