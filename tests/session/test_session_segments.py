"""``segments.json``: each raw segment's counts, kept across a crash and a resume, and their
sums (the crash-and-resume test checks them against real killed daemons)."""

from __future__ import annotations

import json

from gyrostand.runfolder import SEGMENTS_FILE, SegmentLog, read_segments


def _stats(received: int, decoded: int, bins: int, rows: int, late: int = 0) -> dict:
    return {"decoder": {"received": received, "decoded": decoded,
                        "rejected": {"wrong_dlc": received - decoded}},
            "binner": {"bins": bins, "gaps": 1, "late": late, "jumps": 0},
            "samples": {"rows_written": rows, "resumed_bins": {}}}


def test_segments_survive_a_crash_and_sum_over_the_run(tmp_path):
    assert read_segments(tmp_path) == []  # a fresh run folder
    first = SegmentLog(tmp_path, "raw.blf")
    first.update(_stats(100, 98, 10, 9))
    first.update(_stats(250, 247, 25, 24, late=2))  # the last acknowledgement before a kill
    # ... the daemon is killed here; the resumed one reads what the file holds
    before = read_segments(tmp_path)
    assert [(s["raw"], s["state"]) for s in before] == [("raw.blf", "crashed")]
    assert before[0]["decoder"]["decoded"] == 247 and before[0]["rows_written"] == 24
    assert before[0]["ended_by"].startswith("crashed: counts as of its last acknowledgement")
    second = SegmentLog(tmp_path, "raw-2.blf", before)
    second.update(_stats(40, 40, 4, 3), ended_by="stop command",
                  extra={"recorder": {"frames": 40}})
    doc = json.loads((tmp_path / SEGMENTS_FILE).read_text())
    assert [(s["raw"], s["state"]) for s in doc["segments"]] == \
        [("raw.blf", "crashed"), ("raw-2.blf", "finished")]
    assert doc["segments"][1]["ended_by"] == "stop command" and "ended" in doc["segments"][1]
    tot = second.totals()
    assert tot["decoder"] == {"received": 290, "decoded": 287, "rejected": {"wrong_dlc": 3}}
    assert tot["binner"] == {"bins": 29, "gaps": 2, "late": 2, "jumps": 0}
    assert tot["rows_written"] == 27 and tot["recorder"] == {"frames": 40}
    # a finished segment stays finished when the run is resumed again
    assert [s["state"] for s in read_segments(tmp_path)] == ["crashed", "finished"]


def test_a_damaged_segments_file_loses_only_the_counts(tmp_path, caplog):
    (tmp_path / SEGMENTS_FILE).write_text('{"segments": [{"raw": "raw.blf", "sta')
    assert read_segments(tmp_path) == []
    assert "unreadable" in caplog.text and "counts are lost" in caplog.text
