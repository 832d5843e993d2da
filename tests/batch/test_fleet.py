"""The fleet view's statistics on a fleet of known spread, the inputs' errors, and the
message when Dask is missing."""

from __future__ import annotations

import importlib.util
import math

import numpy as np
import pytest

from gyrostand import exitcodes
from gyrostand.batch import fleet
from gyrostand.batch.inputs import collect_runs
from gyrostand.batch.table import write_table
from gyrostand.cli import main
from gyrostand.errors import ConfigError, DataError


def _fleet(seed: int = 3, units: int = 30, runs: int = 6, s_w: float = 0.002,
           s_b: float = 0.01, slope: float = 0.0) -> list[dict]:
    """Rows of ``units`` units x ``runs`` turn-ons: unit means N(0.03, s_b), turn-ons
    N(unit mean, s_w), one run a month, plus ``slope`` per year."""
    rng = np.random.default_rng(seed)
    rows = []
    for u in range(units):
        mean = 0.03 + s_b * rng.standard_normal()
        for k in range(runs):
            v = mean + s_w * rng.standard_normal() + slope * k / 12
            rows.append({"run": f"u{u}-{k}", "serial": f"S{u}", "gyro": "az",
                         "date": f"2026-{k + 1:02d}-01", "type": "FOG-A", "status": "ok",
                         "markov.beta": float(v), "markov.beta_std": 0.001})
    return rows


def test_spreads_recover_turn_on_and_unit_to_unit_std():
    (s,) = fleet.spreads(_fleet(s_w=0.002, s_b=0.01))
    assert s["units"] == 30 and s["runs"] == 180
    # s_w from 150 dof: ~6 % relative error; s_b from 30 unit means (~13 %, plus s_w²/n)
    assert abs(s["turn_on_to_turn_on"] / 0.002 - 1) < 0.2
    assert abs(s["unit_to_unit"] / math.sqrt(0.01 ** 2 + 0.002 ** 2 / 6) - 1) < 0.35


def test_robust_z_flags_the_planted_outlier_and_nothing_else():
    rows = _fleet(s_w=0.002, s_b=0.0005)
    rows[17]["markov.beta"] += 0.05  # 25 turn-on stds off
    rows.append({**rows[0], "run": "other-type", "type": "FOG-B", "markov.beta": 9.0})
    flags = fleet.outliers(rows)
    assert [(f["run"], f["parameter"]) for f in flags] == [(rows[17]["run"], "markov.beta")]
    assert flags[0]["z"] > 10
    # the lone FOG-B run is in a group of its own, too small to judge: not flagged


def test_the_outlier_flags_are_columns_of_fleet_csv_and_parquet(tmp_path):
    """Where people filter (issue 27): the planted outlier's row has its flag and z in
    fleet.csv and fleet.parquet; the lone run of another type has no z (too few to judge);
    a damaged row is not judged."""
    rows = _fleet(s_w=0.002, s_b=0.0005)
    rows[17]["markov.beta"] += 0.05
    rows.append({**rows[0], "run": "other-type", "type": "FOG-B", "markov.beta": 9.0})
    rows.append({**rows[1], "run": "cut-log", "status": "damaged", "log_damage": 3})
    table = fleet.with_outliers(rows)
    flagged = [r for r in table if r.get("outliers")]
    assert [r["run"] for r in flagged] == [rows[17]["run"]]
    assert flagged[0]["outliers"].startswith("markov.beta z=") and flagged[0]["max_abs_z"] > 10
    assert "max_abs_z" not in table[-2] and "max_abs_z" not in table[-1]
    assert all(r["max_abs_z"] <= fleet.Z_LIMIT for r in table[:-2] if r is not flagged[0]
               and r["run"] != rows[17]["run"])
    paths = write_table(table, tmp_path, ["serial", "date", "type"])
    import csv

    with open(paths["csv"], newline="") as fh:
        got = {r["run"]: r for r in csv.DictReader(fh)}
    assert got[rows[17]["run"]]["outliers"].startswith("markov.beta z=")
    assert got["cut-log"]["status"] == "damaged" and got["cut-log"]["max_abs_z"] == ""
    if "parquet" in paths:
        import pyarrow.parquet as pq

        t = pq.read_table(paths["parquet"]).to_pydict()
        i = t["run"].index(rows[17]["run"])
        assert t["max_abs_z"][i] > 10 and t["outliers"][i].startswith("markov.beta")


def test_trend_per_unit_is_the_planted_ageing():
    rows = _fleet(units=3, runs=12, s_w=1e-4, s_b=0.01, slope=0.006)
    tr = fleet.trends(rows)
    assert len(tr) == 3
    for t in tr:
        assert abs(t["slope_per_year"] / 0.006 - 1) < 0.1, t


def test_page_and_table_from_rows(tmp_path):
    rows = _fleet(units=4, runs=3)
    rows[0] = {"run": rows[0]["run"], "serial": "S0", "status": "failed",
               "error": "x.blf: no CAN frame read from the log"}
    paths = write_table(rows, tmp_path, ["serial", "date", "type"])
    assert (tmp_path / "fleet.csv").read_text().splitlines()[0].startswith(
        "run,serial,date,type,gyro,status,error,")
    import pyarrow.parquet as pq

    t = pq.read_table(paths["parquet"]).to_pylist()
    assert len(t) == 12 and t[0]["error"].endswith("no CAN frame read from the log")
    assert t[1]["markov.beta"] == rows[1]["markov.beta"]
    page = fleet.write_view(rows, tmp_path, ["serial", "date", "type"]).read_text()
    assert page.count("<tr") >= 12 and "over dates" in page and 'class="failed"' in page


def test_inputs_name_the_problem(tmp_path):
    log = tmp_path / "a.blf"
    log.write_bytes(b"x")
    with pytest.raises(ConfigError, match="a.blf: a raw log needs the session file"):
        collect_runs([str(log)])
    with pytest.raises(DataError, match="matches no file"):
        collect_runs([str(tmp_path / "*.asc")])
    m = tmp_path / "m.csv"
    m.write_text("serial,date\nS1,2026-01-01\n")
    with pytest.raises(DataError, match="m.csv: line 1: the manifest needs a 'path' column"):
        collect_runs([], manifest=m)
    m.write_text("path,config,serial\na.blf,missing.yaml,S1\n")
    with pytest.raises(ConfigError, match=r"m.csv: line 2: .*missing.yaml: no such session"):
        collect_runs([], manifest=m)
    (tmp_path / "s.yaml").write_text("x: 1\n")
    (tmp_path / "b").mkdir()
    (tmp_path / "b" / "a.blf").write_bytes(b"x")
    runs = collect_runs([str(tmp_path / "**" / "*.blf")], config=tmp_path / "s.yaml")
    assert len(runs) == 2 and len({r.run for r in runs}) == 2  # same stem: names differ
    assert collect_runs([str(tmp_path / "**" / "*.blf")],
                        config=tmp_path / "s.yaml") == runs  # and stay the same


def test_without_dask_the_error_names_the_extra(monkeypatch, capsys):
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *a: None if name == "distributed" else real(name, *a))
    assert main(["batch", "x.blf", "--out", "o"]) == exitcodes.UNAVAILABLE
    assert "pip install 'gyrostand[fleet]'" in capsys.readouterr().err


def test_bad_steps_and_models_are_usage_errors_before_any_work(capsys, tmp_path):
    out = str(tmp_path / "o")
    assert main(["batch", str(tmp_path), "--out", out, "--do", "fit"]) == exitcodes.USAGE
    assert "--do 'fit': steps are replay, identify, diagnose (got fit)" in \
        capsys.readouterr().err
    assert main(["batch", str(tmp_path), "--out", out, "--do", "replay"]) == exitcodes.USAGE
    assert "give identify and/or diagnose" in capsys.readouterr().err
    assert main(["batch", str(tmp_path), "--out", str(tmp_path / "o"), "--model",
                 "markov,nosuchterm"]) == exitcodes.USAGE
    assert "nosuchterm" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_spread_intervals_cover_the_truth_at_their_level():
    """200 fleets of 8 units x 4 turn-ons: the 95 % intervals of s_w and s_b hold the
    true values in 90-99 % of fleets (binomial 3-sigma band around 95 % of 200), and s_b
    with the turn-on part taken out is unbiased enough (median within 10 %)."""
    cover_w = cover_b = 0
    est_b = []
    for seed in range(200):
        (s,) = fleet.spreads(_fleet(seed=seed, units=8, runs=4, s_w=0.004, s_b=0.003))
        lo, hi = s["turn_on_to_turn_on_ci"]
        cover_w += lo <= 0.004 <= hi
        lo, hi = s["unit_to_unit_ci"]
        cover_b += lo <= 0.003 <= hi
        est_b.append(s["unit_to_unit"])
        assert s["unit_means_std"] >= s["unit_to_unit"]
    assert 0.90 <= cover_w / 200 <= 0.99, cover_w
    assert 0.90 <= cover_b / 200 <= 0.995, cover_b
    assert abs(np.median(est_b) / 0.003 - 1) < 0.1, np.median(est_b)


def test_trend_interval_covers_the_planted_slope_and_one_unit_can_be_picked():
    hits = 0
    for seed in range(100):
        rows = _fleet(seed=seed, units=2, runs=6, s_w=0.001, s_b=0.01, slope=0.004)
        (t,) = fleet.trends(rows, "S1")  # one serial: its one gyro
        lo, hi = t["slope_ci"]
        hits += lo <= 0.004 <= hi
        assert t["unit"] == "S1/az" and t["slope_std"] > 0
    assert 88 <= hits <= 100, hits  # 95 % nominal; 3-sigma binomial band of 100
    assert fleet.trends(rows, "S1/az") == fleet.trends(rows, "S1")
    assert fleet.trends(rows, "S9") == []


def test_the_view_has_the_chosen_units_trend(tmp_path):
    rows = _fleet(units=3, runs=5, s_w=1e-4, s_b=0.01, slope=0.006)
    page = fleet.write_view(rows, tmp_path, ["serial", "date", "type"],
                            trend_unit="S2").read_text()
    assert "Trend of S2" in page and 'alt="S2/az markov.beta trend"' in page
    import json

    data = json.loads((tmp_path / "fleet.json").read_text())
    (t,) = data["trend_unit"]["trends"]
    assert t["unit"] == "S2/az" and abs(t["slope_per_year"] / 0.006 - 1) < 0.1


def test_trend_of_an_unknown_serial_is_a_usage_error_before_any_work(capsys, tmp_path):
    (tmp_path / "s.yaml").write_text("x: 1\n")
    (tmp_path / "a.blf").write_bytes(b"x")
    m = tmp_path / "m.csv"
    m.write_text("path,config,serial,date\na.blf,s.yaml,S1,2026-01-01\n")
    assert main(["batch", "--manifest", str(m), "--out", str(tmp_path / "o"),
                 "--trend", "S7"]) == exitcodes.USAGE
    assert "--trend S7: no run of that serial in the inputs (serials: S1)" in \
        capsys.readouterr().err
    assert not (tmp_path / "o").exists()
