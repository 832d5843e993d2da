"""#14: the report as one file to mail (``--single-file``: every figure embedded as a base64
PNG), the IEEE Std 952 Allan figures in the diagnosis and the report (text, JSON, HTML),
and a first figure whose measured trace stays visible under the model."""

from __future__ import annotations

import base64
import contextlib
import io
import json
import re
from pathlib import Path

import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.image import imread

from gyrostand.cli import main
from gyrostand.core.diagnose.allan import drift_tables
from gyrostand.core.ml.fit import ml
from gyrostand.core.model import Model, context
from gyrostand.core.profiles import chamber_profile
from gyrostand.core.simulation import simulate
from gyrostand.report import figures, write_report
from gyrostand.report.page import png_header_size
from gyrostand.report.views import AllanView
from gyrostand.workbench import open_subject, run_diagnose

from .test_report import FIGURES, parse

DATA_URI = "data:image/png;base64,"


def _cli(argv: list[str]) -> str:
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main(argv) == 0
    return buf.getvalue()


@pytest.fixture(scope="module")
def single(chamber_csv, tmp_path_factory) -> Path:
    """``gyrostand report CSV --single-file --out DIR``: the printed path."""
    out = tmp_path_factory.mktemp("single") / "rep"
    out.mkdir()
    (out / "allan.png").write_bytes(b"an earlier folder report's figure")
    return Path(_cli(["report", str(chamber_csv), "--unit", "deg/h", "--single-file",
                      "--out", str(out)]).strip())


def test_single_file_report_is_one_page_with_every_figure_embedded(single):
    assert single.name == "report.html"
    # no PNG (an earlier folder report's removed), no temporary file
    assert [p.name for p in single.parent.iterdir()] == ["report.html"]
    page = parse(single)  # well-formed HTML5: parse() asserts the nesting
    assert page.doctype.lower() == "doctype html"
    assert {"script", "link", "iframe"}.isdisjoint(page.tags)
    assert len(page.imgs) == len(FIGURES) == page.tags.count("figcaption")
    # no reference leaves the file: every src/href is a data URI
    assert page.refs and all(r.startswith(DATA_URI) for r in page.refs), [
        r[:40] for r in page.refs if not r.startswith(DATA_URI)]
    for img in page.imgs:
        png = base64.b64decode(img["src"][len(DATA_URI):], validate=True)
        w, h = png_header_size(png)
        assert (int(img["width"]), int(img["height"])) == (w, h) and w >= 600
        pixels = imread(io.BytesIO(png), format="png")  # decodes the whole image
        assert pixels.shape[:2] == (h, w)
        assert pixels[..., :3].std() > 0.05, f"{img['alt']} is blank"
        assert img["alt"].strip()


def test_single_file_report_has_the_allan_table(single):
    text = " ".join(parse(single).text)
    assert "Allan variance: IEEE Std 952 figures of the drift" in text
    for name in ("angle random walk", "bias instability", "rate random walk", "raw drift",
                 "residual after markov,temp,white,bias", "deg/h·√s", "deg/√h"):
        assert name in text, name


@pytest.fixture(scope="module")
def chamber_report(chamber_csv):
    subject = open_subject(chamber_csv, unit="deg/h")
    return subject, run_diagnose(subject, record=False)


def test_report_json_and_text_carry_the_allan_figures_of_the_allan_command(
        chamber_report, chamber_csv, tmp_path):
    subject, rep = chamber_report
    doc = json.loads(write_report(subject, tmp_path / "j", report=rep,
                                  format="json").read_text())
    allan = json.loads(_cli(["allan", str(chamber_csv), "--unit", "deg/h", "--json"]))
    assert set(doc["allan"]) >= {"raw", "residual", "unit", "dt", "level"}
    assert doc["allan"]["unit"] == "deg/h" and doc["allan"]["model"] == list(rep.model.names)
    for which in ("raw", "residual"):  # one owner: the same numbers as `gyrostand allan`
        assert doc["allan"][which]["figures"] == allan[which]["figures"]
    arw = doc["allan"]["raw"]["figures"]["angle_random_walk"]
    assert arw["unit"] == "deg/h·√s" and arw["ci"][0] < arw["value"] < arw["ci"][1]
    assert doc["allan"]["raw"]["figures"]["bias_instability"]["tau_read"] > 0
    # the diagnosis's own keys are all still there
    assert set(rep.to_dict()) <= set(doc)

    text = write_report(subject, tmp_path / "t", report=rep, format="text").read_text()
    head = "Allan variance (IEEE Std 952 figures), gyro chamber"
    assert head in text and text.index(head) > text.index("candidates, best first")
    assert re.search(r"^N  angle random walk  0\.0\d+ \[", text, re.M)
    # the columns never run into each other (a cell ends in two spaces at least)
    rows = text[text.index(head):].split("\n\n")[1].splitlines()[1:]
    assert [r[:2] for r in rows if r[:1] != " "] == ["N ", "B ", "K ", "R "]
    for line in rows:
        assert not re.search(r"[s\]]\d", line), line  # e.g. "τ = 3 s0.0066"


def test_diagnose_json_has_the_allan_block_and_keeps_its_keys(chamber_csv):
    doc = json.loads(_cli(["diagnose", str(chamber_csv), "--unit", "deg/h", "--json"]))
    for key in ("model", "adequate", "reasons", "parameters", "unit", "loglik", "residual",
                "candidates", "look_alikes", "alpha", "model_error"):
        assert key in doc, key
    assert set(doc["allan"]["raw"]["figures"]) == {"angle_random_walk", "bias_instability",
                                                   "rate_random_walk", "rate_ramp"}
    assert doc["allan"]["residual"]["label"] == "residual after markov,temp,white,bias"


def test_allan_of_a_diagnosis_recovers_a_simulated_gyro():
    """4 h at 1 Hz of a gyro with white noise σ_v = 0.05 (ARW N = σ_v·√Δt = 0.05 y·√s)
    and a rate random walk q = 0.002 y/√s (K = q) under a thermal drift of 30 °C steps:
    the residual's N within 5 % and K within 15 % (its region is short: 4 h gives few
    long averages), and the raw drift's rate ramp (the thermal trend) gone from the
    residual."""
    m = Model.parse("markov,temp,white,bias,random_walk")
    truth = {"markov.beta": 0.01, "markov.sigma": 0.0005, "temp.gamma": -0.0005,
             "white.sigma": 0.05, "bias.b": 0.3, "random_walk.q": 0.002}
    s = simulate(m, truth, chamber_profile(4.0), seed=3)
    fit = ml(s, m)

    class Subject:  # what AllanView.of reads of a workbench subject
        gyro = "sim"
        samples = s

    view = AllanView.of(Subject(), fit, "deg/h")  # type: ignore[arg-type]
    raw, resid = view.raw.figures, view.residual.figures
    assert resid["angle_random_walk"].value == pytest.approx(0.05, rel=0.05)
    assert resid["rate_random_walk"].value == pytest.approx(0.002, rel=0.15)
    lo, hi = resid["angle_random_walk"].lo, resid["angle_random_walk"].hi
    assert lo < 0.05 < hi or abs(resid["angle_random_walk"].value / 0.05 - 1) < 0.02
    assert raw["rate_ramp"].value > 0 and resid["rate_ramp"].value < 0.2 * raw["rate_ramp"].value
    assert (view.raw.label, view.residual.label) == (
        "raw drift", "residual after markov,temp,white,bias,random_walk")
    # the view is the core's tables, no second computation
    r2 = drift_tables(s, fit, unit="deg/h")[1]
    assert r2.figures == view.residual.figures


def _render(fig) -> np.ndarray:
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    return np.asarray(canvas.buffer_rgba())[..., :3].astype(float) / 255.0


def _seen(fig, line) -> tuple[int, float]:
    """How much of ``line`` one sees: the pixels that change when it is hidden, and their
    mean contrast (largest channel change, 0..1)."""
    shown = _render(fig)
    line.set_visible(False)
    hidden = _render(fig)
    line.set_visible(True)
    diff = np.abs(shown - hidden).max(axis=2)
    return int(np.count_nonzero(diff > 0.1)), float(diff[diff > 0.1].mean())


def test_first_figure_keeps_the_measured_trace_visible(chamber_report):
    subject, rep = chamber_report
    s = subject.samples
    p = rep.fit.values
    X = rep.model.regressors(p, context(s, rep.model))
    det = X @ np.array([p[k] for k in rep.model.names_of_kind("linear")])
    fig = figures.measured_vs_model(s, rep, det)
    ax = fig.axes[0]
    lines = {ln.get_gid(): ln for ln in ax.get_lines()}
    meas, model = lines["measured"], lines["model"]
    assert meas.get_label() == "measured" and len(meas.get_xdata()) > 100
    # drawn first (below), opaque enough, wider than the model drawn over it
    assert meas.get_zorder() < model.get_zorder()
    assert (meas.get_alpha() or 1.0) >= 0.8
    assert meas.get_linewidth() > model.get_linewidth()
    # and seen, in contrast and area: the old figure (a 2-pt model over a 0.6-pt trace at
    # alpha 0.55) hid 10.5 % of the trace's pixels and drew it at contrast 0.31; this one
    # hides 3 % at contrast 0.58
    (under, contrast) = _seen(fig, meas)
    model.set_visible(False)
    lines["prediction"].set_visible(False)
    alone, _ = _seen(fig, meas)
    assert alone > 2000 and under > 0.95 * alone, (under, alone)
    assert contrast > 0.5, contrast

