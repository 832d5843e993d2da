"""The run-folder module: the committed-CSV writer, the one torn-last-line rule (reader
and repair), the ledger on top of it, and a resume's repair of a replayed folder."""

from __future__ import annotations

import json
import logging
import os
import sys
from pathlib import Path

import pytest

from gyrostand.can.binning import Bin
from gyrostand.errors import DataError, OutputError
from gyrostand.runfolder import (
    CommittedCSV,
    SamplesWriter,
    cut_torn_tail,
    read_lines,
    read_samples_csv,
    samples_path,
)
from gyrostand.session.resume import prepare_resume
from gyrostand.workbench import append_ledger, read_ledger

DATA = Path(__file__).resolve().parents[1] / "data" / "runfolder"


def test_committed_rows_reach_the_disk_only_at_commit(tmp_path, monkeypatch):
    synced = []
    real = os.fdatasync
    monkeypatch.setattr(os, "fdatasync", lambda fd: (synced.append(fd), real(fd)))
    path = tmp_path / "g" / "table.csv"
    f = CommittedCSV(path, ["t", "x"], sync=True)
    assert not path.exists()  # the constructor only stores
    f.open()
    assert path.read_text() == "t,x\n"
    f.add("0.0,1.5")
    f.add("1.0,nan")
    assert path.read_text() == "t,x\n" and f.pending == 2 and f.rows == 0
    f.commit()
    assert path.read_text() == "t,x\n0.0,1.5\n1.0,nan\n" and f.rows == 2
    assert len(synced) == 1  # one fdatasync per commit, none for an empty one
    f.commit()
    assert len(synced) == 1
    f.close()
    again = CommittedCSV(path, ["t", "x"], append=True)  # a resumed run continues it
    again.open()
    again.add("2.0,3.25")
    again.close()
    assert path.read_text() == "t,x\n0.0,1.5\n1.0,nan\n2.0,3.25\n"


def test_samples_writer_commits_after_before_flush_and_reads_back_exactly(tmp_path):
    order = []
    w = SamplesWriter(tmp_path, ["az", "el"], open_now=False,
                      before_flush=lambda: order.append("raw"))
    assert not samples_path(tmp_path, "az").exists()
    w.open()
    bins = [Bin("az", 1.7e9 + k, k, 0.1 * k + 1e-17, 25.0 + k / 3, 20, 10) for k in range(3)]
    bins.insert(1, Bin("el", 1.7e9, 0, float("nan"), float("nan"), 0, 0))
    w.write(bins)
    assert read_samples_csv(samples_path(tmp_path, "az"))["t"] == []  # not committed yet
    w.flush()
    assert order == ["raw"] and w.rows == 4
    cols = read_samples_csv(samples_path(tmp_path, "az"))
    assert cols["drift"] == [b.drift for b in bins if b.gyro == "az"]  # round-trip floats
    assert cols["temp"] == [b.temp for b in bins if b.gyro == "az"]
    assert samples_path(tmp_path, "el").read_text().splitlines()[1] == "1700000000.0,nan,nan,0,0"
    w.close()


def test_a_table_that_cannot_be_written_names_the_file(tmp_path):
    (tmp_path / "az").write_text("a file where the gyro's folder should be")
    with pytest.raises(OutputError, match="az/samples.csv"):
        SamplesWriter(tmp_path, ["az"])


def test_the_torn_last_line_rule(tmp_path, caplog):
    path = tmp_path / "f.txt"
    path.write_text("a\nb\nc-cut")
    with caplog.at_level(logging.WARNING):
        assert read_lines(path, what="entry") == ["a", "b"]
    assert "line 3: torn last entry left out: 'c-cut'" in caplog.text
    assert read_lines(path, complete=lambda s: s == "c-cut") == ["a", "b", "c-cut"]
    path.write_text("a\nb\n")
    assert read_lines(path) == ["a", "b"]
    path.write_bytes(b"a\n\xff\n")
    with pytest.raises(DataError, match=r"f.txt: not UTF-8 text \(byte 2\)"):
        read_lines(path)


def test_the_torn_last_line_repair(tmp_path):
    path = tmp_path / "f.txt"
    path.write_bytes(b"a\nb\nc-cut")
    assert cut_torn_tail(path) == 5 and path.read_bytes() == b"a\nb\n"
    assert cut_torn_tail(path) == 0 and path.read_bytes() == b"a\nb\n"
    path.write_bytes(b"a\nwhole")
    assert cut_torn_tail(path, complete=lambda b: b == b"whole") == 0
    assert path.read_bytes() == b"a\nwhole\n"
    path.write_bytes(b"header torn")  # not even one whole line
    assert cut_torn_tail(path) == 11 and path.read_bytes() == b""


def test_a_whole_last_ledger_entry_without_line_end_is_kept_and_numbered(tmp_path, caplog):
    led = tmp_path / "ledger.jsonl"
    led.write_text('{"step": 1, "gyro": "az", "model": ["markov"]}\n'
                   '{"step": 2, "gyro": "az", "model": ["markov", "temp"]}')  # hand-edited
    assert [e["step"] for e in read_ledger(led)] == [1, 2]
    e = append_ledger(led, {"gyro": "az", "action": "diagnose", "model": ["markov"]})
    assert e["step"] == 3
    assert [x["step"] for x in read_ledger(led)] == [1, 2, 3]
    with led.open("a") as fh:
        fh.write('{"step": 4, "gy')  # torn while being appended
    assert [x["step"] for x in read_ledger(led)] == [1, 2, 3]
    assert "torn last entry" in caplog.text
    assert append_ledger(led, {"gyro": "az", "model": ["markov"]})["step"] == 4
    assert [x["step"] for x in read_ledger(led)] == [1, 2, 3, 4]


@pytest.fixture(scope="module")
def replayed(tmp_path_factory):
    """A replay of the fixed log of ``tests/data/runfolder`` and its session."""
    sys.path.insert(0, str(DATA))
    try:
        import make_golden
    finally:
        sys.path.remove(str(DATA))
    out = tmp_path_factory.mktemp("replayed")
    cfg = make_golden.config(out)
    from gyrostand.session.offline import run_replay

    rep = run_replay(cfg, DATA / "replay.blf", out=out)
    return cfg, rep.run_dir


def test_resume_cuts_torn_lines_and_estimates_past_the_last_kept_bin(replayed, caplog):
    cfg, run_dir = replayed
    sp, ep = samples_path(run_dir, "az"), run_dir / "az" / "estimates.csv"
    samples, estimates = sp.read_bytes().split(b"\n"), ep.read_bytes().split(b"\n")
    kept = 400  # data rows of samples.csv that were acknowledged
    # a live run's folder (only those are resumed; the replay's files stand for its)
    doc = json.loads((run_dir / "result.json").read_text())
    (run_dir / "result.json").write_text(json.dumps({**doc, "source": "live"}))
    # the daemon died: samples.csv torn inside row kept + 1, estimates.csv 50 rows further
    sp.write_bytes(b"\n".join(samples[:kept + 1]) + b"\n" + samples[kept + 1][:17])
    ep.write_bytes(b"\n".join(estimates[:kept + 51]) + b"\n" + estimates[kept + 51][:30])
    with caplog.at_level(logging.WARNING):
        state = prepare_resume(cfg, run_dir)
    assert sp.read_bytes() == b"\n".join(samples[:kept + 1]) + b"\n"
    assert ep.read_bytes() == b"\n".join(estimates[:kept + 1]) + b"\n"
    assert len(state.columns["az"]["t"]) == kept
    t_last = float(samples[kept].split(b",")[0])
    assert state.estimates_until["az"] == t_last and state.t0 == 1700000000.0
    assert state.last_k(cfg.sampling.dt) == {"az": kept - 1}
    assert state.segment == run_dir / "raw.blf"  # a replay folder has no raw log yet
    assert "cut a torn last line" in caplog.text
    assert "cut estimate rows after the last kept bin" in caplog.text


def test_rows_pending_when_the_raw_log_fails_are_never_written(tmp_path):
    """An acknowledged row replays from the raw log: when ``before_flush`` (the raw log's
    flush) fails, closing the writer drops the pending rows instead of writing them."""
    def raw_full() -> None:
        raise OutputError("raw.blf: cannot write: No space left on device")

    w = SamplesWriter(tmp_path, ["az"], before_flush=raw_full)
    w.write([Bin("az", 0.0, 0, 0.1, 25.0, 20, 10)])
    with pytest.raises(OutputError, match="raw.blf"):
        w.close()
    assert samples_path(tmp_path, "az").read_text() == "t,drift,temp,n_drift,n_temp\n"
    with pytest.raises(OutputError, match="raw.blf"):
        w.close()  # closing again does not start the file over
    assert samples_path(tmp_path, "az").read_text() == "t,drift,temp,n_drift,n_temp\n"
