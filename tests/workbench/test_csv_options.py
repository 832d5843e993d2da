"""A CSV read by every command that takes one: ``--dt`` (the grid step; missing rows are
gaps) and ``--unit`` (the drift's unit, in the tables and the JSON ``unit``)."""

import json

import numpy as np
import pytest

from gyrostand.cli import main
from gyrostand.core.model import Model
from gyrostand.core.profiles import chamber_profile
from gyrostand.core.simulation import simulate


@pytest.fixture
def sparse_csv(tmp_path):
    """A 2-h record on a 10-s grid whose rows for missing samples are left out (4 % of
    them, and a run of 3 in a row), so its smallest step is 10 s only by luck and the
    most common one is 10 s."""
    m = Model.parse("markov,temp,bias")
    s = simulate(m, {"markov.beta": 0.002, "markov.sigma": 0.05, "temp.gamma": -1e-4,
                     "white.sigma": 0.02, "bias.b": 0.3}, chamber_profile(2.0), dt=10.0,
                 seed=3)
    rng = np.random.default_rng(4)
    keep = rng.random(len(s)) >= 0.04
    keep[100:103] = False
    keep[0] = keep[-1] = True
    path = tmp_path / "sparse.csv"
    with path.open("w") as fh:
        fh.write("t,drift,temp\n")
        for t, y, T in zip(s.t[keep], s.drift[keep], s.temp[keep], strict=True):
            fh.write(f"{t:.1f},{y:.6f},{T:.2f}\n")
    return path, int(keep.sum()), len(s)


def test_identify_takes_dt_and_unit(sparse_csv, capsys):
    path, kept, total = sparse_csv
    assert main(["identify", str(path), "--dt", "10", "--unit", "deg/h", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["dt"] == 10.0 and d["n_observed"] == kept and d["n_samples"] == total
    assert d["unit"] == "deg/h"
    assert d["parameter_units"]["temp.gamma"] == "(deg/h)/(s·°C)"
    assert d["parameter_units"]["bias.b"] == "deg/h"
    assert main(["identify", str(path), "--dt", "10", "--unit", "deg/h"]) == 0
    out = capsys.readouterr().out
    assert "residual RMS" in out and out.count("deg/h") >= 3 and " y\n" not in out
    # without --unit the document is as before: no unit key, 'y' in the table
    assert main(["identify", str(path), "--json"]) == 0
    assert "unit" not in json.loads(capsys.readouterr().out)


def test_a_dt_that_does_not_fit_the_rows_is_an_error_naming_the_file(sparse_csv, capsys):
    path, _, _ = sparse_csv
    assert main(["identify", str(path), "--dt", "7"]) != 0
    err = capsys.readouterr().err
    assert str(path.name) in err and "7" in err
