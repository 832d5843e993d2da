"""The CLI contract test-stand automation calls: gyrostand identify ... --json."""

import json
import subprocess
import sys

import numpy as np
import pytest

from gyrostand import exitcodes
from gyrostand.cli import main
from gyrostand.core.model import Model
from gyrostand.core.profiles import paper_profile
from gyrostand.core.simulation import simulate

from ..conftest import truth


@pytest.fixture(scope="module")
def csv_path(tmp_path_factory):
    m = Model.parse("markov,temp,bias")
    s = simulate(m, truth("C1", sigma_v=0.01, **{"bias.b": 0.3}), paper_profile(), seed=51)
    p = tmp_path_factory.mktemp("cli") / "samples.csv"
    s.to_csv(p)
    return p


@pytest.mark.parametrize("method", ["lsq", "lkf", "ml"])
def test_identify_json_contract(method, csv_path, capsys):
    rc = main(["identify", str(csv_path), "--method", method, "--model", "markov,temp,bias",
               "--json"])
    assert rc == 0
    d = json.loads(capsys.readouterr().out)
    assert d["method"] == method
    assert d["model"] == ["markov", "temp", "white", "bias"]
    for name in ("markov.beta", "markov.sigma", "temp.gamma", "white.sigma", "bias.b"):
        assert set(d["parameters"][name]) >= {"value", "std"}
        assert isinstance(d["parameters"][name]["value"], float)
    assert ("loglik" in d) == (method == "ml")
    assert abs(d["parameters"]["temp.gamma"]["value"] / -0.01 - 1) < 0.4


def test_identify_lkf_variants(csv_path, capsys):
    """The default lkf converges (ML's estimate within a fraction of its std); the paper's
    single pass from 1e-4 stays a named variant that says loudly what is wrong with it."""
    assert main(["identify", str(csv_path), "--method", "ml", "--json"]) == 0
    best = json.loads(capsys.readouterr().out)["parameters"]
    assert main(["identify", str(csv_path), "--method", "lkf", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["info"]["variant"] == "relin" and d["info"]["settled"]
    for n in ("markov.beta", "temp.gamma", "bias.b"):
        assert abs(d["parameters"][n]["value"] - best[n]["value"]) <= 0.3 * best[n]["std"], n
    assert main(["identify", str(csv_path), "--method", "lkf", "--variant", "paper",
                 "--json"]) == 0
    p = json.loads(capsys.readouterr().out)
    assert p["info"]["variant"] == "paper"
    assert any(w.startswith("lkf (paper variant):") for w in p["warnings"]), p["warnings"]


def test_identify_sigma_fixes_markov_sigma(csv_path, capsys):
    assert main(["identify", str(csv_path), "--method", "ml", "--sigma", "0.1", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["parameters"]["markov.sigma"] == {"value": 0.1, "std": 0.0, "fixed": True}


def test_identify_table_has_units(csv_path, capsys):
    assert main(["identify", str(csv_path), "--method", "lsq"]) == 0
    out = capsys.readouterr().out
    assert "markov.beta" in out and "1/s" in out and "y/(s·°C)" in out


def test_bad_input_exits_nonzero_with_error_line(tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("t,drift\n0,1\n")
    proc = subprocess.run([sys.executable, "-m", "gyrostand", "identify", str(bad)],
                          capture_output=True, text=True)
    assert proc.returncode == exitcodes.DATAERR
    assert proc.stderr.startswith("error: ") and "missing column(s) temp" in proc.stderr
    assert "Traceback" not in proc.stderr


def test_lsq_refusal_via_cli(csv_path):
    proc = subprocess.run([sys.executable, "-m", "gyrostand", "identify", str(csv_path),
                           "--method", "lsq", "--model", "markov,temp,random_walk"],
                          capture_output=True, text=True)
    assert proc.returncode == exitcodes.USAGE
    assert "lsq cannot represent a sum of random processes" in proc.stderr


def test_debug_shows_the_traceback(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "gyrostand", "--debug", "identify",
                           str(tmp_path / "none.csv")], capture_output=True, text=True)
    assert proc.returncode != 0 and "Traceback" in proc.stderr


def test_core_imports_without_can():
    """The numerical core is hardware-free: it imports with python-can unavailable."""
    code = ("import sys; sys.modules['can'] = None; sys.modules['cantools'] = None; "
            "sys.modules['yaml'] = None; "
            "import gyrostand.core.registry, gyrostand.core.design.fisher, gyrostand.core.simulation; "
            "print('ok')")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert proc.stdout.strip() == "ok", proc.stderr


def test_csv_round_trip_keeps_gaps(tmp_path):
    m = Model.parse("markov,temp")
    s = simulate(m, truth("C1"), paper_profile(), duration=50, seed=1)
    y = s.drift.copy()
    y[5] = np.nan
    from gyrostand.core.data import Samples

    s2 = Samples.from_arrays(s.t, y, s.temp)
    s2.to_csv(tmp_path / "x.csv")
    s3 = Samples.read_csv(tmp_path / "x.csv")
    np.testing.assert_array_equal(s3.drift, s2.drift)
    np.testing.assert_array_equal(s3.temp, s2.temp)
