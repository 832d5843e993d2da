"""Readers skip damage, not data (issue 28, finding 4 and the reader crashes), through
``gyrostand replay`` / ``identify`` / ``batch`` (the CLI's main entry):

- one bad line in a python-can CSV log is skipped, counted (``lines_skipped``) and named
  with its file and line number; every later frame is read (before: "corrupt CAN log: not
  enough values to unpack", the replay failed after 100 frames);
- 40 ASC frame lines cut short anywhere after their first character are 40 skipped lines
  with warnings (before: 38 of them vanished silently, ``lines_skipped 2``);
- a CSV cell over 128 KiB is an error naming the file and line, exit 65 (before:
  ``_csv.Error: field larger than field limit`` as a traceback);
- an empty or headless BLF is an error naming the file, exit 65 (before: "unpack requires
  a buffer of 72 bytes").

Logs written by python-can's own writers (:class:`can.Logger`)."""

from __future__ import annotations

import json
import random

import can
import pytest

from gyrostand import exitcodes
from gyrostand.cli import main as cli_main

from .procs import simulated_session


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    """A 300-s session (20 + 10 frames/s) and its frames."""
    tmp = tmp_path_factory.mktemp("text")
    return simulated_session(tmp)


def _log(path, frames):
    with can.Logger(str(path)) as lg:
        for f in frames:
            lg.on_message_received(f)
    return path


def _replay(cfg_path, log, tmp_path, capsys, *extra):
    rc = cli_main(["replay", str(cfg_path), str(log), "--out", str(tmp_path / "runs"),
                   "--json", *extra])
    out = capsys.readouterr()
    return rc, json.loads(out.out) if rc == 0 else None, out.err


@pytest.mark.parametrize("reader", ["inline", "process"])
def test_one_bad_csv_line_is_skipped_counted_and_named(session, tmp_path, capsys, caplog,
                                                       reader):
    cfg_path, frames = session
    log = _log(tmp_path / "bad.csv", frames)
    lines = log.read_text().splitlines(keepends=True)
    lines[100] = "1700000005.0,0x100,0\n"  # line 101: 3 of 7 values
    log.write_text("".join(lines))
    rc, doc, err = _replay(cfg_path, log, tmp_path, capsys, "--reader", reader)
    assert rc == 0, err
    assert doc["stats"]["log"]["lines_skipped"] == 1
    assert doc["stats"]["log"]["notes"] == [
        f"{log}: line 101: cannot parse, skipped (ValueError: not enough values to unpack "
        f"(expected 7, got 3))"]
    assert doc["stats"]["decoder"]["received"] == len(frames) - 1
    assert f"{log}: line 101: cannot parse" in caplog.text + err


def test_cut_asc_frame_lines_are_skipped_lines_with_warnings(session, tmp_path, capsys):
    cfg_path, frames = session
    log = _log(tmp_path / "cut.asc", frames)
    lines = log.read_text().splitlines(keepends=True)
    rng = random.Random(28)
    body = [i for i, ln in enumerate(lines) if " Tx " in ln]
    cut = sorted(rng.sample(body, 40))
    for i in cut:  # anywhere from the time's second character to before the last byte
        ln = lines[i]
        first = len(ln) - len(ln.lstrip())
        lines[i] = ln[:rng.randint(first + 1, len(ln) - 4)] + "\n"
    log.write_text("".join(lines))
    rc, doc, err = _replay(cfg_path, log, tmp_path, capsys, "--reader", "inline")
    assert rc == 0, err
    assert doc["stats"]["log"]["lines_skipped"] == 40
    assert doc["stats"]["decoder"]["received"] == len(frames) - 40
    notes = doc["stats"]["log"]["notes"]
    assert len(notes) == 20  # the first 20 kept, every one logged
    assert [n.split(": ")[1] for n in notes] == [f"line {i + 1}" for i in cut[:20]]
    assert all("cut short" in n or "cannot parse" in n for n in notes)


def test_an_asc_line_python_can_cannot_parse_is_skipped_and_reading_goes_on(
        session, tmp_path, capsys):
    """python-can's ASC reader raises on a data byte that is not hex; the same reader goes
    on after the line (public API: its header ends again at the line we give it), with
    its start time kept: every other frame at its own time."""
    cfg_path, frames = session
    from gyrostand.can.logs.read import LogDamage, read_log

    log = _log(tmp_path / "bad.asc", frames)
    clean = [m.timestamp for m in read_log(log, LogDamage())]
    lines = log.read_text().splitlines(keepends=True)
    body = [i for i, ln in enumerate(lines) if " Tx " in ln]
    assert len(body) == len(clean) == len(frames)
    bad = [body[100], body[2000]]
    for i in bad:
        lines[i] = lines[i].replace(" d 8 ", " d 8 ZZ ", 1)
    log.write_text("".join(lines))
    rc, doc, err = _replay(cfg_path, log, tmp_path, capsys, "--reader", "inline")
    assert rc == 0, err
    assert doc["stats"]["log"]["lines_skipped"] == 2
    assert doc["stats"]["decoder"]["received"] == len(frames) - 2
    assert [n.split(": ")[1] for n in doc["stats"]["log"]["notes"]] == [
        f"line {i + 1}" for i in bad]
    got = [m.timestamp for m in read_log(log, LogDamage())]
    assert got == [t for k, t in enumerate(clean) if k not in (100, 2000)]


def test_a_csv_cell_over_128_kib_is_an_error_naming_the_line(tmp_path, capsys):
    rows = ["t,drift,temp"] + [f"{i}.0,0.1,20.0" for i in range(10)]
    rows[6] += ',"' + "A" * 200_000 + '"'
    csv = tmp_path / "big.csv"
    csv.write_text("\n".join(rows) + "\n")
    assert cli_main(["identify", str(csv)]) == exitcodes.DATAERR
    assert capsys.readouterr().err == (f"error: {csv}: line 7: not CSV (field larger than "
                                       f"field limit (131072))\n")
    man = tmp_path / "man.csv"
    man.write_text('path\n"' + "A" * 200_000 + '"\n')
    assert cli_main(["batch", "--out", str(tmp_path / "b"), "--manifest", str(man)]) == \
        exitcodes.DATAERR
    assert capsys.readouterr().err == (f"error: {man}: line 2: not CSV (field larger than "
                                       f"field limit (131072))\n")


@pytest.mark.parametrize("size, what", [(0, "empty file (0 bytes)"),
                                        (50, "50 bytes, shorter than a BLF file header "
                                             "(72 bytes)")])
def test_an_empty_blf_is_an_error_naming_it(session, tmp_path, capsys, size, what):
    cfg_path, frames = session
    whole = _log(tmp_path / "whole.blf", frames[:100]).read_bytes()
    log = tmp_path / "empty.blf"
    log.write_bytes(whole[:size])
    rc, _, err = _replay(cfg_path, log, tmp_path, capsys)
    assert rc == exitcodes.DATAERR
    assert err.splitlines()[-1] == f"error: {log}: not a BLF log: {what}"
