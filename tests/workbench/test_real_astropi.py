"""Real data: the Astro Pi ground record (../shared/data/astropi/, see its README).

One gyro axis is written as a CSV the way such a record arrives: one row per sample at its
own timestamp (cadence 9–11 s, missing seconds simply absent, an 11.9-h outage), the rate
in deg/h, the HTS221 temperature beside it. ``identify`` and ``diagnose`` must read it
without a grid error, catch the jolt when the unit was moved (t ≈ 38,360 s), and say
something physically sane: the output is bias-compensated, so no temperature effect is
significant (a short warm-up at most).
"""

import csv
import datetime as dt
import io
import json
import math
import zipfile
from pathlib import Path

import pytest

from gyrostand.cli import main
from gyrostand.workbench import open_subject, run_diagnose

ROOT = Path(__file__).resolve().parents[2]
ZIP = ROOT.parent / "shared" / "data" / "astropi" / "astro_pi_data_20150824_085954.zip"
RAD_S_TO_DEG_H = 180.0 / math.pi * 3600.0

pytestmark = pytest.mark.skipif(not ZIP.exists(), reason=f"{ZIP} not present")


@pytest.fixture(scope="module")
def axis_csv(tmp_path_factory):
    """gyro_y (deg/h) and temp_h (degC) at their own epoch times, one row per sample."""
    with zipfile.ZipFile(ZIP) as z:
        name = next(n for n in z.namelist() if n.endswith(".csv"))
        text = z.read(name).decode("utf-8")
    path = tmp_path_factory.mktemp("astropi") / "astropi_gyro_y.csv"
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["t", "drift", "temp"])
        for row in csv.DictReader(io.StringIO(text)):
            t = dt.datetime.fromisoformat(row["time_stamp"]).replace(tzinfo=dt.UTC)
            w.writerow([f"{t.timestamp():.0f}", f"{float(row['gyro_y']) * RAD_S_TO_DEG_H:.4f}",
                        row["temp_h"]])
    return path


def test_a_real_irregular_record_is_read_and_judged_sanely(axis_csv, capsys):
    subject = open_subject(axis_csv, unit="deg/h")
    s = subject.samples
    assert s.dt == 10.0  # the record's own step, not its smallest (9 s) one
    assert s.n_observed == 24604
    assert any("missing time steps filled as gaps" in w for w in s.warnings)

    assert main(["identify", str(axis_csv), "--json"]) == 0
    ident = json.loads(capsys.readouterr().out)
    assert ident["n_observed"] <= 24604 - 2  # the jolt's samples are left out

    rep = run_diagnose(subject, record=False)
    jolt = [w for w in rep.fit.warnings if "spike" in w]
    assert jolt, rep.fit.warnings
    t0 = s.t[0]
    assert "38360 s from the first sample" in jolt[0] or "3836" in jolt[0], jolt
    table = [(c.term, round(c.lr_stat, 1), f"{c.p_value:.2g}", c.note) for c in rep.candidates]
    print("verdict:", "ADEQUATE" if rep.adequate else "NOT ADEQUATE", rep.reasons)
    print("candidates:", table)
    assert t0 > 1.4e9
    temperature_effects = {"temp2", "temp_lag", "temp_rate", "hysteresis"}
    assert not {c.term for c in rep.significant} & temperature_effects, table
    assert {c.term for c in rep.significant} <= {"warmup"}, table
    gamma = rep.fit.parameters["temp.gamma"]
    assert abs(gamma.value) < 3 * gamma.std or abs(gamma.value) * 7.0 / (
        rep.fit.parameters["markov.beta"].value) < 100.0  # < 100 deg/h over the 7-degC span
