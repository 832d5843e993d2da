"""One input rule for the workbench (issue 24, item 5): ``identify``, ``diagnose``, ``fit``,
``report`` and ``allan`` read a run folder, a samples CSV, the Parquet export and a raw
log with ``--config`` alike (:mod:`gyrostand.workbench.inputs`), with the DBC's units.

A 1000-s simulated stand (10 Hz frames) is written as a BLF and an ASC, and each is
replayed into a run folder: a raw log read with ``--config`` gives the numbers of the run
folder its replay made, exactly (the same decoding and binning, in memory). (The ASC's
text timestamps put its bins on another grid than the BLF's: its own replay is the
reference.)"""

from __future__ import annotations

import copy
import json
from pathlib import Path

import pytest
import yaml

from gyrostand import exitcodes
from gyrostand.cli import main
from gyrostand.workbench.inputs import input_kind, read_input

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def stand(tmp_path_factory):
    """(session file, BLF, ASC, run folder of the BLF's replay, of the ASC's)."""
    tmp = tmp_path_factory.mktemp("inputs")
    d = copy.deepcopy(yaml.safe_load((ROOT / "configs" / "demo.yaml").read_text()))
    d["session"] = {"name": "inputs", "output": str(tmp / "runs")}
    d["dbc"] = str(ROOT / "dbc" / "gyrostand.dbc")
    d["gyros"][0]["identifiers"] = ["ml"]
    d["simulate"].update(duration=1000, rates={"drift": 10, "temperature": 10})
    cfg = tmp / "stand.yaml"
    cfg.write_text(yaml.safe_dump(d))
    blf, asc = tmp / "stand.blf", tmp / "stand.asc"
    for log in (blf, asc):
        assert main(["simulate", str(cfg), "--log", str(log), "-q"]) == 0
    runs = []
    for log in (blf, asc):
        out = tmp / f"replayed-{log.suffix[1:]}"
        assert main(["replay", str(cfg), str(log), "--out", str(out), "-q"]) == 0
        runs += [p.parent for p in out.rglob("result.json")]
    return cfg, blf, asc, *runs


def _json(capsys, argv: list[str]) -> dict:
    capsys.readouterr()
    assert main([*argv, "--json", "-q"]) == 0
    return json.loads(capsys.readouterr().out)


def _numbers(doc: dict) -> dict:
    """A fit's numbers (its parameters, log-likelihood, residual RMS), provenance left out."""
    return {k: doc[k] for k in ("parameters", "loglik", "residual_rms", "model", "unit")
            if k in doc}


def test_identify_takes_the_run_folder(stand, capsys):
    _, _, _, run, _ = stand
    capsys.readouterr()
    assert main(["identify", str(run), "-q"]) == 0
    out = capsys.readouterr().out
    assert "model markov,temp,white" in out  # the run's model, not the CSV default
    assert "(deg/h)/(s·°C)" in out and "residual RMS" in out
    assert " y" not in out and "y/" not in out  # the DBC's unit, never `y`


def test_a_raw_log_with_its_session_gives_the_run_folder_s_numbers(stand, capsys):
    cfg, blf, asc, run, run_asc = stand
    for log, replayed in ((blf, run), (asc, run_asc)):
        on_run = _json(capsys, ["identify", str(replayed)])
        on_log = _json(capsys, ["identify", str(log), "--config", str(cfg)])
        assert _numbers(on_log) == _numbers(on_run)
        assert on_log["unit"] == "deg/h"
    d_run = _json(capsys, ["diagnose", str(run)])
    d_log = _json(capsys, ["diagnose", str(blf), "--config", str(cfg)])
    for doc in (d_run, d_log):
        for c in doc["candidates"]:
            c.pop("seconds")
        doc["reference"].pop("seconds", None)
        doc["allan"].pop("source")
    assert d_log == d_run  # every number: verdict, candidates, reference, Allan tables


def test_the_parquet_export_round_trips(stand, capsys, tmp_path):
    pytest.importorskip("pyarrow")
    _, _, _, run, _ = stand
    assert main(["export", str(run), "--parquet", "--out", str(tmp_path)]) == 0
    pq = tmp_path / "az" / "samples.parquet"
    assert input_kind(pq) == "parquet"
    src, ref = read_input(pq), read_input(run)
    assert (src.gyro, src.unit) == ("az", "deg/h")
    for a, b in ((src.samples.t, ref.samples.t), (src.samples.temp, ref.samples.temp),
                 (src.samples.counts, ref.samples.counts)):
        assert (a == b).all()
    assert ((src.samples.drift == ref.samples.drift)
            | (src.samples.drift != src.samples.drift)).all()
    on_pq = _json(capsys, ["identify", str(pq), "--model", "markov,temp"])
    on_run = _json(capsys, ["identify", str(run), "--model", "markov,temp"])
    assert _numbers(on_pq) == _numbers(on_run)


def test_a_samples_csv_of_a_run_takes_the_run_s_gyro_and_units(stand):
    _, _, _, run, _ = stand
    src = read_input(run / "az" / "samples.csv")
    assert (src.gyro, src.unit, src.origin) == ("az", "deg/h", "csv")


def test_a_raw_log_without_its_session_is_refused_naming_config(stand, capsys):
    cfg, blf, _, run, _ = stand
    for cmd in ("identify", "diagnose", "fit", "report", "allan"):
        capsys.readouterr()
        assert main([cmd, str(blf), "-q"]) == exitcodes.USAGE
        err = capsys.readouterr().err
        assert f"{blf}: a raw CAN log" in err and "--config SESSION.yaml" in err, err
    assert main(["identify", str(run), "--config", str(cfg), "-q"]) == exitcodes.USAGE
    assert "only a raw CAN log needs a session file" in capsys.readouterr().err


def test_a_log_of_another_stand_names_the_mapping(stand, tmp_path, capsys):
    cfg = stand[0]
    other = tmp_path / "other.asc"
    other.write_text("date Mon Jan 1 00:00:00.000 am 2024\nbase hex  timestamps absolute\n"
                     "   0.001000 1  7FF             Rx   d 1 00\n"
                     "   0.002000 1  7FF             Rx   d 1 00\n")
    assert main(["identify", str(other), "--config", str(cfg), "-q"]) == exitcodes.DATAERR
    err = capsys.readouterr().err
    assert "decoded none of 2 CAN frames through the DBC mapping" in err, err


def test_a_fifo_is_refused_without_blocking(tmp_path, capsys):
    """Issue 28: identify on a FIFO blocked for ever."""
    import os

    from gyrostand.cli import main

    fifo = tmp_path / "run.csv"
    os.mkfifo(fifo)
    assert main(["identify", str(fifo)]) == exitcodes.NOINPUT
    assert "not a regular file or a run folder" in capsys.readouterr().err
