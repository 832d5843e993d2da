"""The outputs the renderers must keep byte-identical: every command that prints a result,
in text and JSON, on a seeded synthetic chamber run (1 h, a hidden temp_rate effect,
quantized temperature) and on a replay of a simulated CAN log (300 s, jitter, drops).

``python -m tests.render.make_golden`` (from the repository root) writes ``golden/``; the
files there were made by this script on main c05478b, before the renderers were one package,
and ``test_golden.py`` compares today's outputs with them byte for byte. Remade once since, for
a change of the numbers' last digits and not of a renderer (session 26, #25: ML's score pass
holds its settled covariance derivatives, so every search's gradient moved by ~1e-13
relative; the searches stop within their tolerance of the same optima: values within 1e-7,
standard errors within 2e-5 relative, a search-bound parameter's std ``markov2.beta`` and two
noise levels at ~0 moved more — each of them a flat direction), and once more for
``diagnose.json`` alone (session 27, #25: the hysteresis term's own regressor slopes in the
score replace central differences of its tanh, ~1e-10 relative; its candidate's refit stops
within 1e-8 relative of the same optimum, ln L 4e-11 higher; no other number moved), and for
``diagnose.txt``/``.json`` (session 29, #23: the level shift's and the periodic line's lines
and keys added; no other byte changed). Temporary paths
print as ``<TMP>``, a run folder's wall-clock stamp as ``<STAMP>``, this interpreter's
``-m gyrostand`` in a printed command as ``gyrostand``, a
wall-clock duration as ``<S>``; the HTML report's time stamps (its own, the ledger's) as ``<NOW>``.
"""

from __future__ import annotations

import contextlib
import io
import re
import sys
from collections.abc import Callable
from pathlib import Path

from gyrostand.cli import main
from tests.report.conftest import chamber_samples

HERE = Path(__file__).resolve().parent
GOLDEN = HERE / "golden"
ROOT = HERE.parents[1]

#: name of the golden file -> the command's arguments ({csv}, {cfg}, {log}, {tmp} filled in)
COMMANDS: dict[str, list[str]] = {
    "identify_ml.txt": ["identify", "{csv}", "--method", "ml"],
    "identify_ml.json": ["identify", "{csv}", "--method", "ml", "--json"],
    "identify_lsq.txt": ["identify", "{csv}", "--method", "lsq"],
    "identify_lkf.txt": ["identify", "{csv}", "--method", "lkf", "--model", "markov,temp"],
    "identify_lkf.json": ["identify", "{csv}", "--method", "lkf", "--model", "markov,temp",
                          "--json"],
    "diagnose.txt": ["diagnose", "{csv}", "--unit", "deg/h"],
    "diagnose.json": ["diagnose", "{csv}", "--unit", "deg/h", "--json"],
    "fit.txt": ["fit", "{csv}", "--unit", "deg/h", "--model", "markov,temp,bias", "--add",
                "temp_rate"],
    "fit.json": ["fit", "{csv}", "--unit", "deg/h", "--model", "markov,temp,bias", "--add",
                 "temp_rate", "--json"],
    "fit_remove.txt": ["fit", "{csv}", "--model", "markov,temp,bias,temp_rate", "--remove",
                       "temp_rate"],
    "allan.txt": ["allan", "{csv}", "--unit", "deg/h"],
    "allan.json": ["allan", "{csv}", "--unit", "deg/h", "--json"],
    "simulate.txt": ["simulate", "{cfg}", "--log", "{log}"],
    "replay.txt": ["replay", "{cfg}", "{log}", "--out", "{tmp}/rep"],
}


def _run(argv: list[str]) -> str:
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        code = main(argv)
    if code != 0:
        raise RuntimeError(f"gyrostand {' '.join(argv)} exited {code}")
    return out.getvalue()


def _session(tmp: Path) -> Path:
    """The demo session on a virtual channel, 300 s of frames at 20/10 Hz."""
    import copy

    import yaml

    d = copy.deepcopy(yaml.safe_load((ROOT / "configs" / "demo.yaml").read_text()))
    d["session"]["output"] = str(tmp / "runs")
    d["bus"] = {"interface": "virtual", "channel": "gyrostand-golden",
                "preserve_timestamps": True}
    d["dbc"] = str(ROOT / "dbc" / "gyrostand.dbc")
    d["simulate"].update(duration=300.0, rates={"drift": 20, "temperature": 10})
    path = tmp / "s.yaml"
    path.write_text(yaml.safe_dump(d))
    return path


def outputs(tmp: Path, only: Callable[[str], bool] = lambda _: True) -> dict[str, str]:
    """Every golden output made afresh under ``tmp`` (in the order of :data:`COMMANDS`:
    ``fit`` reads the ledger ``diagnose`` wrote), plus the replay's ``report.txt`` and the
    HTML report (time stamp masked)."""
    tmp = Path(tmp)
    csv = tmp / "chamber.csv"
    chamber_samples().to_csv(csv)
    fill = {"csv": str(csv), "cfg": str(_session(tmp)), "log": str(tmp / "sim.blf"),
            "tmp": str(tmp)}
    got: dict[str, str] = {}
    for name, argv in COMMANDS.items():
        if only(name):
            got[name] = _run([a.format(**fill) for a in argv])
    if only("replay_report.txt"):
        line = next(x for x in got["replay.txt"].splitlines() if x.startswith("report:"))
        got["replay_report.txt"] = Path(line.split(None, 1)[1]).read_text()
    if only("report.html"):
        page = Path(_run(["report", str(csv), "--unit", "deg/h"]).strip())
        got["report.html"] = re.sub(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d(\+00:00)?", "<NOW>",
                                    page.read_text())
    return {k: _mask(v, tmp) for k, v in got.items()}


def _mask(text: str, tmp: Path) -> str:
    """Temporary paths, run-folder stamps, wall-clock durations (``"seconds"`` keys) and
    this interpreter in a printed command (``<python> -m gyrostand``: ``gyrostand``)."""
    import shlex

    text = text.replace(f"{shlex.quote(sys.executable)} -m gyrostand", "gyrostand")
    text = re.sub(r"-\d{8}-\d{6}\b", "-<STAMP>", text.replace(str(tmp), "<TMP>"))
    return re.sub(r'"seconds": [0-9.e+-]+', '"seconds": <S>', text)


if __name__ == "__main__":
    import tempfile

    with tempfile.TemporaryDirectory() as d:
        made = outputs(Path(d))
    GOLDEN.mkdir(exist_ok=True)
    for name, text in made.items():
        (GOLDEN / name).write_text(text)
        print(f"wrote {GOLDEN / name} ({len(text)} characters)", file=sys.stderr)
