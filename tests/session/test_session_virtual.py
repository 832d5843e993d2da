"""The daemon end to end on python-can's virtual bus: the simulated stand's frames in, the
daemon's response frames read back from the bus and decoded with the DBC; the recorded BLF
replayed to the same 1-s samples and the same final fits."""

from __future__ import annotations

import json
import math
from itertools import pairwise

import pytest
from sessionhelpers import TRUTH, decode, last_results, make_cfg, run_virtual

from gyrostand.can.replay import paced, read_log
from gyrostand.session.offline import run_replay, simulated_frames

PARAMS = ("markov.beta", "markov.sigma", "temp.gamma", "white.sigma")  # model order
BETA, GAMMA = PARAMS.index("markov.beta"), PARAMS.index("temp.gamma")
LKF, LSQ, ML = 0, 1, 2


@pytest.fixture(scope="module")
def live(tmp_path_factory):
    """The paper's 2000-s scenario (case C2), 10 Hz per channel, LKF linearised at the
    truth with σ known (where the paper's filter is at its best)."""
    out = tmp_path_factory.mktemp("live")
    cfg = make_cfg(out, lkf={"beta0": 0.0333, "gamma0": -0.001, "sigma": 0.1,
                             "white_sigma": 0.001})
    outcome, seen, stand = run_virtual(cfg, simulated_frames(cfg))
    return cfg, outcome, seen, stand


def test_response_frames_recover_the_truth(live):
    cfg, outcome, seen, stand = live
    assert outcome.ok and outcome.stop_reason == "stop command"
    assert stand.ack == {"Command": 2, "Sequence": 1, "Result": 0, "Reason": 0, "Node": 1}
    res = last_results(cfg, seen, "GS_RESULT_1")
    assert set(res) == {LKF, LSQ, ML} and all(len(p) == len(PARAMS) for p in res.values())
    # online LKF (at the truth's point) and LSQ within 3 std, final ML within 4 std
    for ident, k in ((LKF, 3), (LSQ, 3), (ML, 4)):
        for i, name in ((BETA, "markov.beta"), (GAMMA, "temp.gamma")):
            v, s = res[ident][i]
            assert 0 < s < abs(TRUTH[name]), (ident, name, v, s)
            assert abs(v - TRUTH[name]) < k * s, (ident, name, v, s)
    # the frames carry the final ML of result.json (as float32)
    doc = json.loads(outcome.result_json.read_text())
    ml = doc["gyros"]["az"]["fits"]["ml"]["parameters"]
    for i, name in enumerate(PARAMS):
        assert res[ML][i][0] == pytest.approx(ml[name]["value"], rel=1e-6, abs=1e-12)
    summ = {d["Identifier"]: d for d in decode(cfg, seen, "GS_SUMMARY_1")}
    assert summ[ML]["ModelTerms"] == 0b111 and summ[ML]["Status"] in (0, 1)
    assert summ[LKF]["Samples"] == 2001 and summ[ML]["ResidualRms"] > 0


def test_heartbeat_counts_and_files(live):
    cfg, outcome, seen, stand = live
    # beats before the first data frame carry the wall clock (silent bus): skip them
    first = next(i for i, f in enumerate(seen) if f.arbitration_id in (0x100, 0x110))
    seen = seen[first:]
    pages = decode(cfg, seen, "GS_STATUS")
    p0 = [p for p in pages if p["Page"] == 0]
    p1 = [p for p in pages if p["Page"] == 1]
    # at most one beat per second of frame time (faster than real time: one per step)
    assert 10 < len(p0) <= 2001 + 1 and len(p1) == len(p0)
    assert all((b["Counter"] - a["Counter"]) % 16 == 1 for a, b in pairwise(p0))
    ts = [f.timestamp for f in seen if f.arbitration_id == 0x500 and f.data[0] & 0xF == 0]
    assert all(b - a >= 1.0 - 1e-6 for a, b in pairwise(ts[:-1]))  # the last: at stop
    assert ts[-1] >= ts[-2]
    states = [p["State"] for p in p0]
    assert states[0] == 1 and states[-1] == 3 and set(states) <= {1, 2, 3}  # ... stopped
    assert p0[-1]["Bins"] == 2001 and p0[-1]["Gaps"] == outcome.stats["binner"]["gaps"]
    assert p1[-1]["FramesDecoded"] == stand.sent + 1  # every frame and the stop command
    assert p1[-1]["FramesRejected"] == 0
    run = outcome.run_dir
    for f in ("raw.blf", "az/samples.csv", "az/estimates.csv", "result.json", "report.txt",
              "run.log"):
        assert (run / f).is_file(), f
    assert sum(1 for _ in read_log(run / "raw.blf")) == stand.sent + 1
    est = (run / "az" / "estimates.csv").read_text().splitlines()
    assert len(est) == 1 + 2001 and est[0].startswith("t,lkf:markov.beta,lkf:markov.beta:std")
    assert est[-1].endswith(",ok") and "nan" not in est[-1]
    report = outcome.report.read_text()
    assert "markov.beta" in report and "ml" in report and "frames received" in report
    # units from the DBC's drift signal (deg/h), not the model's placeholder y
    gamma_row = next(ln for ln in report.splitlines() if ln.startswith("temp.gamma"))
    assert gamma_row.endswith("(deg/h)/(s·°C)"), gamma_row
    doc = json.loads(outcome.result_json.read_text())
    g = doc["gyros"]["az"]
    assert set(g["fits"]) == {"lkf", "lkf_batch", "lsq", "ml"} and g["bins"] == 2001
    assert doc["stats"]["recorder"]["frames"] == stand.sent + 1
    assert doc["stats"]["commands"]["acked"] == 1


@pytest.mark.parametrize("parallel", [False, True], ids=["in-process", "reader-process"])
def test_replay_of_the_recorded_blf_reproduces_the_run(live, tmp_path, parallel):
    cfg, outcome, _, _ = live
    rep = run_replay(cfg, outcome.run_dir / "raw.blf", out=tmp_path, parallel=parallel)
    a = (outcome.run_dir / "az" / "samples.csv").read_bytes()
    assert (rep.run_dir / "az" / "samples.csv").read_bytes() == a
    live_doc = json.loads(outcome.result_json.read_text())
    rep_doc = json.loads(rep.result_json.read_text())
    for m in ("lkf", "lkf_batch", "lsq", "ml"):
        assert rep_doc["gyros"]["az"]["fits"][m]["parameters"] == \
            live_doc["gyros"]["az"]["fits"][m]["parameters"], m
    assert rep_doc["stats"]["decoder"] == live_doc["stats"]["decoder"]
    assert rep_doc["source"].startswith("replay of")
    # the online estimates follow the same bins too
    assert (rep.run_dir / "az" / "estimates.csv").read_bytes() == \
        (outcome.run_dir / "az" / "estimates.csv").read_bytes()
    assert math.isfinite(rep_doc["gyros"]["az"]["fits"]["ml"]["loglik"])


@pytest.mark.parametrize("fsync", [True, False])
def test_acknowledgements_reach_the_disk_raw_log_first(tmp_path, monkeypatch, fsync):
    """session.fsync (default on): each acknowledgement fdatasyncs the raw log before
    samples.csv (and estimates.csv), so an acknowledged row replays from the raw log
    after a power cut too; off: no syncs at all."""
    import os

    synced: list[str] = []
    real = os.fdatasync

    def spy(fd: int) -> None:
        synced.append(os.path.basename(os.readlink(f"/proc/self/fd/{fd}")))
        real(fd)

    monkeypatch.setattr(os, "fdatasync", spy)
    d = {"name": "durable", "output": str(tmp_path)}
    if not fsync:
        d["fsync"] = False
    cfg = make_cfg(tmp_path, duration=120.0, session=d)
    # 120 s of frames paced at 40x: ~3 s of wall time, so several 1-s acknowledgements
    outcome, _, _ = run_virtual(cfg, paced(simulated_frames(cfg), 40.0))
    assert outcome.ok
    if not fsync:
        assert synced == []
        return
    assert synced.count("samples.csv") >= 3 and synced.count("estimates.csv") >= 3
    last_raw = -1
    for i, name in enumerate(synced):
        if name == "raw.blf":
            last_raw = i
        elif name == "samples.csv":
            assert last_raw >= 0, synced  # the raw log was synced before the rows
            last_raw = -1  # and must be synced again before the next rows
    rows = (outcome.run_dir / "az" / "samples.csv").read_text().count("\n") - 1
    assert rows == 121
