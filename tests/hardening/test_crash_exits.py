"""Crashes of the third hostile round (issue 28, "Crashes"), through the command line's
main entry: each is one clear ``error: ...`` line naming the problem and an exit status
by its kind (64 usage, 65 data, 66 input)
(before: a traceback from ValueError, scipy's _MaxFuncCallError, numpy's
_ArrayMemoryError after trying to allocate 26.8 GiB, and pathlib's RuntimeError)."""

from __future__ import annotations

import random

import pytest

from gyrostand import exitcodes
from gyrostand.cli import main as cli_main

MODEL = ["--model", "markov,temp", "--param", "markov.beta=0.03", "--param",
         "markov.sigma=0.1", "--param", "temp.gamma=-0.001"]


def _rc(argv):
    try:
        return cli_main(argv)
    except SystemExit as exc:  # argparse's usage error
        return exc.code


def _series(path, n):
    rng = random.Random(1)
    path.write_text("t,drift,temp\n" + "".join(
        f"{i}.0,{0.1 + rng.gauss(0, 0.01):.5f},{20 + 0.02 * i:.3f}\n" for i in range(n)))
    return path


@pytest.mark.parametrize("n", [8, 12, 15])
def test_allan_on_fewer_than_16_samples(tmp_path, capsys, n):
    csv = _series(tmp_path / "short.csv", n)
    assert _rc(["allan", str(csv)]) == exitcodes.DATAERR
    assert capsys.readouterr().err == (f"error: {csv}: an Allan table needs at least 16 "
                                       f"samples of drift, got {n}\n")


def test_allan_on_16_samples_works(tmp_path, capsys):
    csv = _series(tmp_path / "ok.csv", 16)
    assert _rc(["allan", str(csv)]) == 0
    assert "raw drift" in capsys.readouterr().out


def test_design_with_zero_evaluations_is_a_usage_error(tmp_path, capsys):
    assert _rc(["design", *MODEL, "--evaluations", "0", "--out", str(tmp_path)]) == exitcodes.USAGE
    assert "argument --evaluations: must be >= 1, got '0'" in capsys.readouterr().err
    assert not any(tmp_path.iterdir())


@pytest.mark.parametrize("hours", ["1e6", "1e300"])
def test_design_longer_than_memory_holds_says_so_before_allocating(tmp_path, capsys,
                                                                   hours):
    from gyrostand.cli.design_program import BYTES_PER_SAMPLE, available_memory

    free = available_memory()
    assert free is not None and free < 1e6 * 3600 * BYTES_PER_SAMPLE  # (any machine)
    assert _rc(["design", *MODEL, "--hours", hours, "--out", str(tmp_path)]) == exitcodes.USAGE
    err = capsys.readouterr().err
    h = f"{float(hours):g}"
    assert err.startswith(f"error: --hours {h}: a {h}-h program on a 1-s grid (")
    assert err.endswith(" GiB is available: give fewer --hours\n") and err.count("\n") == 1


def test_batch_on_a_symlink_loop(tmp_path, capsys, monkeypatch):
    (tmp_path / "a").symlink_to(tmp_path / "b")
    (tmp_path / "b").symlink_to(tmp_path / "a")
    monkeypatch.chdir(tmp_path)
    assert _rc(["batch", "a", "--out", str(tmp_path / "out")]) == exitcodes.NOINPUT
    err = capsys.readouterr().err
    assert err.startswith("error: a: cannot resolve the path (") and err.count("\n") == 1
    assert "ymlink" in err or "symbolic links" in err
