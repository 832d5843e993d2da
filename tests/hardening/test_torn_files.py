"""What a killed writer leaves, file by file (issue 5, item 2, the readers' side).

* BLF: every prefix of a recorder's file (a kill can cut the file anywhere in its last
  append) reads with ``read_log`` as a prefix of the recorded frames, exact; python-can's
  own reader fails on some of these cuts (the reason ``read_log`` handles the tail).
* CSV and JSON lines: a last line without its line end is left out with a warning by
  ``read_samples_csv``, ``Samples.read_csv``, the report's ``read_estimates`` and the
  ledger reader; damage elsewhere is still an error naming the file and line.
"""

from __future__ import annotations

import logging

import can
import pytest

from gyrostand.can.logs.read import LogDamage
from gyrostand.can.recorder import Recorder
from gyrostand.can.replay import read_log
from gyrostand.core.data import Samples
from gyrostand.errors import DataError
from gyrostand.report.series import read_estimates
from gyrostand.runfolder import read_samples_csv
from gyrostand.workbench import read_ledger


def test_every_prefix_of_a_recorded_blf_reads_as_a_prefix_of_its_frames(tmp_path, caplog):
    path = tmp_path / "raw.blf"
    rec = Recorder(path, max_container_size=512)  # many containers in a small file
    sent = [can.Message(timestamp=1.7e9 + 0.01 * i, arbitration_id=0x100 + i % 3,
                        is_extended_id=False, data=i.to_bytes(8, "little"))
            for i in range(120)]
    for i, m in enumerate(sent):
        rec.on_message_received(m)
        if i % 20 == 19:
            rec.flush()
    rec.stop()
    data = path.read_bytes()

    def key(m: can.Message) -> tuple:
        return (round(m.timestamp, 6), m.arbitration_id, bytes(m.data))

    want = [key(m) for m in sent]
    cut = tmp_path / "cut.blf"
    plain_failures = torn = 0
    caplog.set_level(logging.ERROR)
    for end in range(144, len(data) + 1, 5):  # every 5th cut point (all: ~5x longer)
        cut.write_bytes(data[:end])
        got = [key(m) for m in read_log(cut)]
        assert got == want[:len(got)]
        try:
            list(can.BLFReader(cut))
        except Exception:
            plain_failures += 1
        torn += 1
    assert [key(m) for m in read_log(path)] == want
    assert torn > 350 and plain_failures > 0  # python-can alone cannot read every cut


def test_damage_inside_a_blf_is_skipped_counted_and_reading_goes_on(tmp_path, caplog):
    path = tmp_path / "raw.blf"
    with Recorder(path, max_container_size=512) as rec:
        for i in range(200):
            rec.on_message_received(can.Message(timestamp=1.7e9 + i, arbitration_id=0x100,
                                                is_extended_id=False, data=bytes(8)))
    data = bytearray(path.read_bytes())
    data[400:404] = b"XXXX"  # an object signature in the middle
    path.write_bytes(bytes(data))
    damage = LogDamage()
    got = [m.timestamp for m in read_log(path, damage)]
    assert damage.containers == 1 and "raw.blf: damaged container at byte" in caplog.text
    assert 150 < len(got) < 200 and got[-1] == 1.7e9 + 199  # one container lost, no more
    assert got == sorted(got) and set(got) <= {1.7e9 + i for i in range(200)}


ROWS = ["t,drift,temp,n_drift,n_temp",
        "1700000000.0,0.1,25.0,100,10",
        "1700000001.0,0.2,25.1,100,10",
        "1700000002.0,0.3,25.2,100,10"]


@pytest.mark.parametrize("cut", [1, 12, 16, 20, 25])
def test_samples_readers_leave_out_a_torn_last_line(tmp_path, cut, caplog):
    path = tmp_path / "samples.csv"
    path.write_text("\n".join(ROWS) + "\n" + "1700000003.0,0.4,25.3,100,10"[:cut])
    cols = read_samples_csv(path)
    assert cols["t"] == [1700000000.0, 1700000001.0, 1700000002.0]
    assert "torn last line" in caplog.text
    s = Samples.read_csv(path)
    assert len(s) == 3 and any("torn last line" in w for w in s.warnings)


def test_a_complete_last_line_without_line_end_is_kept_by_the_core_reader(tmp_path):
    path = tmp_path / "hand.csv"  # a hand-written CSV without the final newline
    path.write_text("t,drift,temp\n0,0.1,25\n1,0.2,25.5")
    s = Samples.read_csv(path)
    assert len(s) == 2 and not any("torn" in w for w in s.warnings)


def test_damage_before_the_last_line_is_still_an_error(tmp_path):
    path = tmp_path / "samples.csv"
    path.write_text("\n".join(ROWS[:2] + ["17000000", *ROWS[2:]]) + "\n")
    with pytest.raises(DataError, match="samples.csv"):
        read_samples_csv(path)


def test_estimates_and_ledger_readers_leave_out_a_torn_last_line(tmp_path, caplog):
    est = tmp_path / "estimates.csv"
    est.write_text("t,lsq:markov.beta,lsq:markov.beta:std,lsq:status\n"
                   "0.0,0.03,0.001,ok\n1.0,0.031,0.001,ok\n2.0,0.0")
    conv = read_estimates(est)
    assert conv and len(conv[0].t) == 2
    led = tmp_path / "ledger.jsonl"
    led.write_text('{"step": 1, "gyro": "az", "model": ["markov"]}\n{"step": 2, "gy')
    assert read_ledger(led) == [{"step": 1, "gyro": "az", "model": ["markov"]}]
    assert "torn last entry" in caplog.text
    led.write_text('{"step": 1}\n{"step": 2, "gy\n{"step": 3}\n')
    with pytest.raises(DataError, match="line 2"):
        read_ledger(led)
