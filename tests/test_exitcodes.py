"""Exit statuses are BSD sysexits (issue 27 item 3, ``gyrostand.exitcodes``), through the
command line: argparse's usage errors are 64 (not argparse's 2), each error kind has its
status, an uncaught exception is 70 with one line (not Python's 1 and a traceback), a
replay that decodes nothing is 65 with one ``error:`` line, and ``gyrostand --help``
lists the table."""

from __future__ import annotations

import errno
import subprocess
import sys
from pathlib import Path

import can
import pytest

from gyrostand import errors, exitcodes
from gyrostand.cli import main


def _gyrostand(*argv: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "gyrostand", *argv], capture_output=True,
                          text=True, timeout=120)


def test_the_numbers_are_bsd_sysexits():
    assert (exitcodes.OK, exitcodes.USAGE, exitcodes.DATAERR, exitcodes.NOINPUT,
            exitcodes.UNAVAILABLE, exitcodes.SOFTWARE, exitcodes.CANTCREAT, exitcodes.IOERR,
            exitcodes.CONFIG) == (0, 64, 65, 66, 69, 70, 73, 74, 78)
    assert exitcodes.NO_RESTART == (64, 65, 66, 78)


def test_a_usage_error_exits_64_in_a_process():
    r = _gyrostand("replay", "--no-such-option")
    assert r.returncode == exitcodes.USAGE, r.stderr
    assert r.stderr.startswith("usage: gyrostand replay")
    assert r.stderr.splitlines()[-1].startswith("gyrostand replay: error: ")
    r = _gyrostand("no-such-command")
    assert r.returncode == exitcodes.USAGE and "invalid choice" in r.stderr


def test_help_lists_every_status():
    r = _gyrostand("--help")
    assert r.returncode == 0
    table = r.stdout.split("exit status (BSD sysexits.h", 1)[1].splitlines()[1:]
    assert [int(line.split()[0]) for line in table if line.strip()] == list(
        exitcodes.MEANING)


@pytest.mark.parametrize("exc,status", [
    (errors.UsageError("x"), 64),
    (errors.ModelError("x"), 64),
    (errors.DataError("x"), 65),
    (errors.IdentificationError("x"), 65),
    (errors.LogError("x"), 65),
    (errors.NoInputError("x"), 66),
    (errors.LogNotFoundError("x"), 66),
    (errors.SessionFileNotFoundError("x"), 66),
    (errors.BusUnavailableError("x"), 69),
    (errors.MissingPackageError("x"), 69),
    (errors.OutputError("x"), 73),
    (errors.ConfigError("x"), 78),
    (errors.CanEdgeError("x"), 78),
    (FileNotFoundError(errno.ENOENT, "x"), 66),
    (OSError(errno.ENOSPC, "x"), 74),
    (RuntimeError("x"), 70),
    (KeyboardInterrupt(), 130),
])
def test_each_error_kind_has_its_status(exc, status):
    assert exitcodes.exit_status(exc) == status


def test_a_failed_write_is_74_a_folder_that_cannot_be_made_73():
    for code, status in ((errno.ENOSPC, 74), (errno.EIO, 74), (errno.ENOENT, 74),
                         (errno.EACCES, 73), (errno.EROFS, 73), (errno.EEXIST, 73)):
        exc = errors.OutputError("x")
        exc.__cause__ = OSError(code, "x")
        assert exitcodes.exit_status(exc) == status, errno.errorcode[code]


def test_an_uncaught_exception_is_70_with_one_line(monkeypatch, capsys, tmp_path):
    import gyrostand.cli.allan as allan

    def boom(args):
        raise ZeroDivisionError("a bug")

    monkeypatch.setattr(allan, "run", boom)
    assert main(["allan", str(tmp_path)]) == exitcodes.SOFTWARE
    err = capsys.readouterr().err
    assert err == ("error: internal error: ZeroDivisionError: a bug (rerun with --debug for "
                   "the traceback, and please report it)\n")
    with pytest.raises(ZeroDivisionError):
        main(["allan", str(tmp_path), "--debug"])


def test_a_replay_that_decodes_nothing_exits_65_with_one_error_line(tmp_path):
    cfg = Path(__file__).resolve().parent.parent / "configs" / "demo.yaml"
    log = tmp_path / "other.blf"
    with can.Logger(str(log)) as w:
        for i in range(200):
            w.on_message_received(can.Message(timestamp=1000 + 0.01 * i,
                                              arbitration_id=0x7AB, data=bytes(8),
                                              is_extended_id=False))
    r = _gyrostand("replay", str(cfg), str(log), "--out", str(tmp_path / "runs"), "-q")
    assert r.returncode == exitcodes.DATAERR, r.stderr
    lines = [line for line in r.stderr.splitlines() if line.startswith("error: ")]
    assert len(lines) == 1 and lines[0].startswith(
        "error: replay decoded none of 200 frames (unknown_id 200); the mapped messages "
        "are "), r.stderr
    missing = _gyrostand("replay", str(cfg), str(tmp_path / "none.blf"), "-q")
    assert missing.returncode == exitcodes.NOINPUT
    assert missing.stderr == f"error: {tmp_path / 'none.blf'}: log file not found\n"
