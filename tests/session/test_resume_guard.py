"""Resume only continues a live folder of the same mapping, and re-anchors a clock that
went back (issue 28, findings 2 and 10):

- ``gyrostand run --resume REPLAY_FOLDER`` is exit 78 (CONFIG) naming the folder's source (before:
  accepted, then ``"source": "live"`` with a raw log lacking the earlier rows);
- ``run --resume`` with another drift (or temperature) message is exit 78 naming
  ``gyros[0].drift`` (before: two sensors in one samples.csv);
- a crashed/stopped live folder resumed while the stand's clock went back 100 s or 5000 s:
  the new frames are a clock step re-anchored after the kept bins, every one binned
  (before: exit 0, ``late`` = every sample, zero bins added)."""

from __future__ import annotations

import can
import pytest
import yaml
from sessionhelpers import make_cfg, run_virtual, write_cfg_yaml

from gyrostand import exitcodes
from gyrostand.cli import main as cli_main
from gyrostand.runfolder import read_samples_csv, samples_path
from gyrostand.session.offline import run_replay, simulated_frames


@pytest.fixture(scope="module")
def live(tmp_path_factory):
    out = tmp_path_factory.mktemp("resume")
    cfg = make_cfg(out, duration=60.0)
    frames = list(simulated_frames(cfg))
    outcome, _, _ = run_virtual(cfg, frames)
    return out, cfg, frames, outcome.run_dir


def test_a_replay_folder_is_not_resumed(live, tmp_path, capsys):
    out, cfg, frames, _ = live
    rep = run_replay(cfg, frames, out=tmp_path / "rep")
    yml = write_cfg_yaml(tmp_path / "s.yaml", tmp_path, dict(cfg.bus))
    assert cli_main(["run", str(yml), "--resume", str(rep.run_dir)]) == exitcodes.CONFIG
    err = capsys.readouterr().err
    assert f"{rep.run_dir}: a folder of a 'replay of <frames>', not of a live run" in err


def test_another_drift_message_is_not_resumed(live, tmp_path, capsys):
    out, cfg, frames, run_dir = live
    yml = write_cfg_yaml(tmp_path / "s.yaml", tmp_path, dict(cfg.bus))
    d = yaml.safe_load(yml.read_text())
    d["gyros"][0]["drift"] = {"message": "GYRO_DRIFT_2", "signal": "Drift"}
    yml.write_text(yaml.safe_dump(d))
    assert cli_main(["run", str(yml), "--resume", str(run_dir)]) == exitcodes.CONFIG
    err = capsys.readouterr().err
    assert ("gyros[0].drift: GYRO_DRIFT_2 (0x101, standard).Drift in deg/h differs from "
            "the run folder's GYRO_DRIFT_1 (0x100, standard).Drift in deg/h") in err


@pytest.mark.parametrize("back", [100.0, 5000.0])
def test_resume_with_the_clock_gone_back_bins_every_new_frame(tmp_path, back):
    cfg = make_cfg(tmp_path, duration=60.0)
    frames = list(simulated_frames(cfg))
    half = len(frames) // 2
    first, _, _ = run_virtual(cfg, frames[:half])
    kept = len(read_samples_csv(samples_path(first.run_dir, "az"))["t"])
    t_last = read_samples_csv(samples_path(first.run_dir, "az"))["t"][-1]
    later = [can.Message(timestamp=f.timestamp - back, arbitration_id=f.arbitration_id,
                         is_extended_id=f.is_extended_id, data=bytes(f.data))
             for f in frames[half:]]
    second, _, _ = run_virtual(cfg, later, resume=first.run_dir)
    assert second.run_dir == first.run_dir
    cols = read_samples_csv(samples_path(first.run_dir, "az"))
    assert second.stats["binner"]["late"] == 0
    assert second.stats["decoder"]["clock_steps"] == 1
    new = [t for t in cols["t"] if t > t_last]
    assert len(cols["t"]) - kept == len(new) >= 29  # ~30 s of frames: ~30 new bins
    assert min(new) - t_last <= 2 * cfg.sampling.dt  # re-anchored right after the kept
