"""The run/replay/simulate/demo subcommands: exit codes, printed paths, errors."""

from __future__ import annotations

import json
import re
from pathlib import Path

from sessionhelpers import DEMO, ROOT, write_cfg_yaml

from gyrostand import exitcodes
from gyrostand.can.replay import read_log
from gyrostand.cli import main
from gyrostand.cli.demo import find_demo_config


def _cfg(tmp_path, channel="gyrostand-cli"):
    return write_cfg_yaml(tmp_path / "s.yaml", tmp_path / "runs",
                          {"interface": "virtual", "channel": channel,
                           "preserve_timestamps": True},
                          duration=100.0, rates={"drift": 20, "temperature": 10})


def test_simulate_to_a_log_then_replay_it(tmp_path, capsys):
    cfg = _cfg(tmp_path)
    log = tmp_path / "sim.blf"
    assert main(["simulate", str(cfg), "--log", str(log)]) == 0
    n = sum(1 for _ in read_log(log))
    assert capsys.readouterr().out.strip() == f"wrote {n} frames to {log}"
    assert 3000 < n <= 3030  # 101 s (t = 0..100) x 30 Hz, 0.1 % dropped
    assert main(["replay", str(cfg), str(log), "--out", str(tmp_path / "rep")]) == 0
    out = capsys.readouterr().out
    assert "stopped: end of log" in out and "markov.beta" in out
    result = next(line.split(None, 1)[1] for line in out.splitlines()
                  if line.startswith("result:"))
    doc = json.loads(open(result).read())
    assert doc["gyros"]["az"]["bins"] == 101 and doc["source"] == f"replay of {log}"
    # the same log parsed by a reader process: the same samples, the same fits
    assert main(["replay", str(cfg), str(log), "--out", str(tmp_path / "rep2"),
                 "--reader", "process"]) == 0
    out2 = capsys.readouterr().out
    result2 = next(line.split(None, 1)[1] for line in out2.splitlines()
                   if line.startswith("result:"))
    doc2 = json.loads(open(result2).read())

    def fits(doc: dict, result: str) -> dict:  # each fit names its own run folder's file
        out = {}
        for method, fit in doc["gyros"]["az"]["fits"].items():
            if "error" in fit:  # e.g. the online lkf still in its warm-up (101 bins)
                out[method] = fit
                continue
            assert fit.pop("source") == f"{Path(result).parent.name}/az/samples.csv"
            out[method] = fit
        return out

    assert fits(doc2, result2) == fits(doc, result)
    assert (Path(result2).parent / "az" / "samples.csv").read_bytes() == \
        (Path(result).parent / "az" / "samples.csv").read_bytes()


def test_demo_runs_from_another_folder(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert find_demo_config() == ROOT / "configs" / "demo.yaml" == DEMO
    cfg = _cfg(tmp_path, "gyrostand-cli-demo")
    assert main(["demo", "--clean", "--config", str(cfg), "--out", str(tmp_path / "d")]) == 0
    out = capsys.readouterr().out
    assert "stop acknowledged" in out and "stopped: stop command" in out
    assert "truth" in out and "report:" in out
    # the demo says what numba compiled in it (nothing, once the caches are written)
    assert re.search(r"numba: (every kernel loaded from its cache \(nothing compiled\)|"
                     r"nothing compiled \(the kernels were compiled at install, "
                     r"gyrostand\.core\._kernels\)|"
                     r"first run: \d+ kernel compilation\(s\) in [\d.]+ s \(.+\)); "
                     r"demo [\d.]+ s in all", out)


def test_the_demo_runs_the_loop_the_product_exists_for(tmp_path, capsys):
    """The default demo: a hidden effect (temp2) on the stand; diagnose says NOT ADEQUATE
    with temp2 first; fit --add temp2 cuts the open-loop error by >= 70 %; the verdict is
    then ADEQUATE; the daemon's next run on the adopted model estimates temp2.gamma2
    online within 4 std of the truth; the truth is named only at the end."""
    cfg = write_cfg_yaml(tmp_path / "s.yaml", tmp_path / "runs",
                         {"interface": "virtual", "channel": "gyrostand-cli-loop",
                          "preserve_timestamps": True}, rates={"drift": 20, "temperature": 10})
    assert main(["demo", "--config", str(cfg), "--out", str(tmp_path / "d")]) == 0
    out = capsys.readouterr().out
    steps = [out.index(f"=== {k}.") for k in range(1, 7)]
    assert steps == sorted(steps)
    diagnose1, fit, diagnose2, run2 = (out[steps[k]:steps[k + 1]] for k in range(1, 5))
    assert "temp2" not in out[:steps[1]]  # the truth is not shown before the end
    assert "verdict  NOT ADEQUATE" in diagnose1
    first = re.search(r"^\* (\w+) ", diagnose1, re.M)
    assert first and first.group(1) == "temp2"
    assert "--add temp2" in fit and "temp2.gamma2" in fit
    fall = re.search(r"open-loop model error ([\d.]+) -> ([\d.]+) deg/h", out)
    assert fall and float(fall.group(2)) <= 0.3 * float(fall.group(1))
    assert "verdict  ADEQUATE" in diagnose2
    row = re.search(r"^temp2\.gamma2\s+(\S+)\s+(\S+) ± (\S+)", run2, re.M)
    assert row, run2
    truth, value, std = (float(x) for x in row.groups())
    assert truth == -2e-4 and abs(value - truth) <= 4 * std
    assert "lkf = the online LKF at stop" in run2
    assert out.count("html report (az") == 2
    assert "the loop found it, and the model with it is ADEQUATE" in out


def test_the_compile_clock_counts_a_compilation_and_names_it():
    from numba import njit

    from gyrostand.cli.compiling import CompileClock

    @njit
    def never_cached_kernel(x):
        return x * 2.0 + 1.0

    with CompileClock() as clock:
        assert never_cached_kernel(1.5) == 4.0
        assert never_cached_kernel(2.5) == 6.0  # the same signature: no second compile
    assert clock.kernels == 1 and clock.seconds > 0
    assert clock.names == ["never_cached_kernel"]
    assert "1 kernel compilation(s)" in clock.line() and "never_cached_kernel" in clock.line()
    with CompileClock() as again:
        never_cached_kernel(3.5)
    assert again.kernels == 0 and "nothing compiled" in again.line()


def test_errors_exit_by_their_kind_with_a_message(tmp_path, capsys):
    assert main(["run", str(tmp_path / "missing.yaml")]) == exitcodes.NOINPUT
    assert "error:" in capsys.readouterr().err
    assert main(["simulate", str(ROOT / "tests" / "data" / "foreign.yaml")]) == exitcodes.CONFIG
    assert "simulate: missing" in capsys.readouterr().err
    assert main(["replay", str(_cfg(tmp_path)), str(tmp_path / "none.blf")]) == exitcodes.NOINPUT
    assert "log file not found" in capsys.readouterr().err
