"""A truncated MF4 log is one error line, exit 65 (issue 28, "Crashes"): before, the error
was followed by asammdf's "Exception ignored in: <function MDF4.__del__ ...>" traceback
(its half-opened reader failing to close at garbage collection)."""

from __future__ import annotations

import subprocess
import sys

import can
import pytest

from gyrostand import exitcodes

from .procs import DEMO, ROOT

pytest.importorskip("asammdf")


def test_a_truncated_mf4_is_one_error_line(tmp_path):
    log = tmp_path / "whole.mf4"
    with can.Logger(str(log)) as lg:
        for i in range(3000):
            lg.on_message_received(can.Message(timestamp=1_700_000_000 + 0.01 * i,
                                               arbitration_id=0x100, is_extended_id=False,
                                               data=bytes(8)))
    raw = log.read_bytes()
    cut = tmp_path / "cut.mf4"
    cut.write_bytes(raw[:len(raw) // 2])
    r = subprocess.run([sys.executable, "-m", "gyrostand", "replay", str(DEMO),
                        str(cut), "--out", str(tmp_path / "runs")], capture_output=True,
                       text=True, cwd=ROOT, timeout=120)
    assert r.returncode == exitcodes.DATAERR
    lines = r.stderr.splitlines()  # the progress line of the stage, then the error
    assert lines[-1].startswith(f"error: {cut}: cannot read CAN log: "), r.stderr
    assert "Exception ignored" not in r.stderr and "Traceback" not in r.stderr, r.stderr
    assert len(lines) <= 2, r.stderr
