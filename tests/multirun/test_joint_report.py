"""``gyrostand report RUN RUN ...``: the joint report's page and its figures (each run's
measured drift with the joint open-loop model, the per-run biases with the repeatability,
each run's residual check, the ranked candidates), as the single-run report is tested."""

from __future__ import annotations

import base64

import numpy as np
import pytest
from matplotlib.image import imread

from gyrostand.core.data import Samples
from gyrostand.report.joint import FIGURES, joint_plots, write_joint_report
from gyrostand.report.page import png_size
from gyrostand.workbench.joint import run_joint_diagnose
from gyrostand.workbench.subject import open_subjects

from ..report.test_report import parse
from ..workbench.framelike import frame_run

BIASES = (0.2, 0.45, 0.3)


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """Three 1.5-h runs that arrived as frames (jitter, drops, partial bins, quantized
    temperature) with a temperature-rate effect and their own turn-on biases."""
    d = tmp_path_factory.mktemp("joint")
    return [frame_run(d / f"run{r + 1}.csv", ("temp_rate",), {"temp_rate.k": 3.0},
                      seed=80 + r, hours=1.5, drift_hz=4.0, temp_hz=2.0, drop=0.01,
                      params={"bias.b": b}) for r, b in enumerate(BIASES)]


@pytest.fixture(scope="module")
def page(runs, tmp_path_factory):
    out = tmp_path_factory.mktemp("rep") / "joint"
    path = write_joint_report(open_subjects(runs, model="markov,temp,bias"), out)
    return path, out


def test_the_page_has_every_figure_as_a_png_that_exists(page):
    path, out = page
    assert path == out / "report.html"
    p = parse(path)
    assert p.doctype.lower() == "doctype html"
    assert {"script", "link", "iframe"}.isdisjoint(p.tags)
    assert [i["src"] for i in p.imgs] == list(FIGURES)
    assert p.tags.count("figcaption") == len(FIGURES)
    for img in p.imgs:
        png = out / img["src"]
        w, h = png_size(png)
        assert img["alt"].strip() and (int(img["width"]), int(img["height"])) == (w, h)
        pixels = imread(png)
        assert pixels.shape[:2] == (h, w) and w >= 600
        assert pixels[..., :3].std() > 0.05, f"{img['src']} is blank"
    assert {f.name for f in out.iterdir()} == set(FIGURES) | {"report.html"}
    text = " ".join(p.text)
    # the tables are there too: the repeatability and the hidden effect first
    assert "turn-on repeatability of bias.b" in text
    first = text.split("missing effects")[1].split("\n")[2].split()
    assert first[0] == "temp_rate", first


def test_the_figures_draw_each_run_and_the_joint_numbers(runs):
    """The figures' content: one panel per run whose model line is the run's open-loop
    response at the joint estimate (its own bias), the biases plotted are the joint fit's
    per-run ones with their intervals, the candidates bar the hidden effect first."""
    subjects = open_subjects(runs, model="markov,temp,bias")
    rep = run_joint_diagnose(subjects, record=False)
    plots = dict((p.file, make) for p, make in joint_plots(subjects, rep))
    assert list(plots) == list(FIGURES)
    fig = plots["joint_measured_vs_model.png"]()
    panels = [ax for ax in fig.axes if any(ln.get_gid() == "model" for ln in ax.lines)]
    assert len(panels) == 3
    for r, ax in enumerate(panels):
        s = Samples.read_csv(runs[r])
        model = next(ln for ln in ax.lines if ln.get_gid() == "model").get_ydata()
        # the open-loop response is the run's own bias plus the shared thermal part: its
        # mean tracks the measured drift's, and the runs' offsets are their biases
        b = rep.fit.parameters[f"bias.b@{r + 1}"].value
        assert abs(float(np.mean(model)) - float(np.mean(s.drift))) < 0.05
        assert abs(b - BIASES[r]) < 0.05
        assert f"run {r + 1}: " in ax.get_title(loc="left")
    fig = plots["joint_biases.png"]()
    (ax,) = fig.axes
    rp = rep.fit.repeatability
    assert rp is not None
    ys = [ln.get_ydata() for ln in ax.lines if len(ln.get_ydata()) == 3]
    assert any(np.allclose(y, rp.values) for y in ys), (ys, rp.values)
    assert f"{rp.spread:.3g}" in ax.get_title()
    fig = plots["joint_candidates.png"]()
    (ax,) = fig.axes
    labels = [t.get_text() for t in ax.get_yticklabels()]
    assert labels[0].startswith("1. temp_rate"), labels  # the top bar: the hidden effect
    fig = plots["joint_residual_checks.png"]()
    assert len(fig.axes) == 2


def test_single_file_embeds_the_figures(runs, tmp_path):
    out = tmp_path / "one"
    path = write_joint_report(open_subjects(runs[:2], model="markov,temp,bias"), out,
                              single_file=True)
    assert {f.name for f in out.iterdir()} == {"report.html"}
    p = parse(path)
    assert len(p.imgs) == len(FIGURES)
    for img in p.imgs:
        head, data = img["src"].split(",", 1)
        assert head == "data:image/png;base64"
        assert base64.b64decode(data)[:8] == b"\x89PNG\r\n\x1a\n"



def test_the_command_passes_single_file_to_the_joint_report(runs, tmp_path, capsys):
    from gyrostand.cli import main

    out = tmp_path / "cli"
    assert main(["report", *map(str, runs[:2]), "--model", "markov,temp,bias",
                 "--single-file", "--out", str(out)]) == 0
    assert capsys.readouterr().out.strip() == str(out / "report.html")
    assert {f.name for f in out.iterdir()} == {"report.html"}
    assert all(i["src"].startswith("data:image/png;base64,")
               for i in parse(out / "report.html").imgs)
