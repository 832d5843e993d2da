"""Where the open-loop error fails per segment of the profile, as the text shows it: one
line for a short run (unchanged), a table by kind of segment for a long one."""

import numpy as np

from gyrostand.cli import main
from gyrostand.core.data import Samples
from gyrostand.core.diagnose.verdict import fit_error
from gyrostand.core.ml.fit import ml
from gyrostand.core.model import Model
from gyrostand.report.segments import LINE_MAX, open_loop_by_segment
from gyrostand.report.text import model_error

from ..workbench.framelike import frame_run


def _seg(kind, t0, t1, rms, floor=0.04, unexpl=0.0):
    return ({"kind": kind, "t_start": t0, "t_stop": t1},
            {"rms": rms, "floor": floor, "unexplained": unexpl})


def test_a_short_run_keeps_its_one_line_and_a_long_one_gets_a_table_by_kind():
    run = ({"kind": "run", "t_start": 0.0, "t_stop": 1.0}, {"rms": 0.1})
    segs = [_seg("heating", 0, 99, 0.2, unexpl=0.19), _seg("soak", 100, 199, 0.03),
            _seg("cooling", 200, 299, 0.15, unexpl=0.14)]
    ranges = [run[0], *(g for g, _ in segs)]
    rows = [run[1], *(r for _, r in segs)]
    assert open_loop_by_segment(ranges, rows, 60.0, "deg/h") == [
        "  open loop per segment (60-s means, deg/h): heating 0–99 s 0.2; soak 100–199 s "
        "0.03; cooling 200–299 s 0.15"]
    # LINE_MAX + 1 segments: the table (a segment without windows is left out)
    many = [_seg("heating", 0, 99, 0.2, unexpl=0.19), _seg("soak", 100, 199, 0.03),
            _seg("heating", 200, 299, 0.25, floor=0.05, unexpl=0.24),
            _seg("soak", 300, 399, 0.05, unexpl=0.01), _seg("cooling", 400, 499, 0.04),
            _seg("soak", 500, 599, 0.02), _seg("heating", 600, 699, 0.03)]
    assert len(many) == LINE_MAX + 1
    ranges = [run[0], *(g for g, _ in many), {"kind": "soak", "t_start": 700, "t_stop": 710}]
    rows = [run[1], *(r for _, r in many), {"rms": None, "floor": None, "unexplained": None}]
    out = open_loop_by_segment(ranges, rows, 60.0, "deg/h")
    assert out[0].startswith("  open loop per segment (60-s means, deg/h), 7 segments by kind")
    assert out[2:] == [
        "    heating           3      2         0.2  0.25 at 200–299 s (floor 0.05)",
        "    soak              3      1        0.03  0.05 at 300–399 s (floor 0.04)",
        "    cooling           1      0        0.04  0.04 at 400–499 s (floor 0.04)"]
    assert open_loop_by_segment(ranges[:1], rows[:1], 60.0, "deg/h") == []


def test_a_long_run_with_a_hidden_rate_effect_fails_on_its_ramps_not_its_soaks(tmp_path,
                                                                             capsys):
    """A 6-h chamber cycle built from frames (jitter, partial first and last bins,
    quantised sensor) with a hidden dT/dt effect, diagnosed on the base model: the table
    has one row per kind, its counts are the segments', and the ramps are where the
    open-loop error leaves its floor; with temp_rate added no ramp stays above it."""
    path = frame_run(tmp_path / "six.csv", ["temp_rate"], {"temp_rate.k": 10.0}, seed=41,
                     hours=6.0, drift_hz=2.0, temp_hz=2.0)
    s = Samples.read_csv(path)
    base = ml(s, Model.parse("markov,temp,white,bias"))
    err = fit_error(base, s, "deg/h")
    kinds = [g["kind"] for g in err.ranges[1:]]
    assert len(kinds) > LINE_MAX
    text = model_error(err)
    i = next(k for k, ln in enumerate(text) if "segments by kind" in ln)
    table = {ln.split()[0]: ln.split() for ln in text[i + 2:]}
    assert set(table) == set(kinds)
    for kind, cols in table.items():
        assert int(cols[1]) == kinds.count(kind)
    rows = err.entries[(0.0, err.windows_s[0])][1:]
    above = {k: sum((r["unexplained"] or 0) > 0 for g, r in zip(err.ranges[1:], rows,
                                                              strict=True) if g["kind"] == k)
             for k in table}
    assert {k: int(c[2]) for k, c in table.items()} == above
    # a dT/dt effect: the fast heating ramps leave the floor, no soak does, and the
    # worst segment is a heating one (this profile cools slowly: a small effect there)
    assert above["heating"] >= 1 and above["soak"] == 0, above
    worst = max(zip(err.ranges[1:], rows, strict=True), key=lambda gr: gr[1]["rms"] or 0)
    assert worst[0]["kind"] == "heating"
    t0 = err.ranges[0]["t_start"]
    assert t0 > 1e9  # a log's epoch times: the text counts from the run's start
    assert f"at {worst[0]['t_start'] - t0:.0f}–{worst[0]['t_stop'] - t0:.0f} s" in \
        text[i + 2 + list(table).index("heating")]
    # the effect added: no ramp stays above its floor (of 11 segments each judged at its
    # 99 % point, one may exceed by chance: here the last soak, by 5 %), the median falls
    fixed = ml(s, Model.parse("markov,temp,white,bias,temp_rate"))
    err2 = fit_error(fixed, s, "deg/h")
    rows2 = err2.entries[(0.0, err2.windows_s[0])][1:]
    out = [g["kind"] for g, r in zip(err2.ranges[1:], rows2, strict=True)
           if (r["unexplained"] or 0) > 0]
    assert len(out) <= 1 and not set(out) & {"heating", "cooling"}, out
    assert np.median([r["rms"] for r in rows2]) < np.median([r["rms"] for r in rows])
    # the command's text: both per-segment tables count from the run's start
    assert main(["-q", "diagnose", str(path)]) == 0
    out = capsys.readouterr().out
    assert "NOT ADEQUATE" in out and "segments by kind" in out
    inno = out.split("per segment of the temperature profile")[1].splitlines()
    assert inno[2].split()[:2] == ["soak", "0"]
    assert "1700" not in out.split("candidates, best first")[0].split("model error")[1]
