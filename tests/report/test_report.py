"""``gyrostand report``: the folder, the page (valid structure, tables, every image a PNG
that exists), the ledger and the convergence source, the CLI."""

import contextlib
import io
import json
import shutil
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest
from matplotlib.image import imread

from gyrostand import exitcodes
from gyrostand.cli import main
from gyrostand.core.data import Samples
from gyrostand.core.lkf.filter import lkf
from gyrostand.core.model import Model
from gyrostand.report import default_dir, write_report
from gyrostand.report.page import png_size
from gyrostand.report.series import envelope, ledger_points, read_estimates
from gyrostand.runfolder import estimate_columns
from gyrostand.workbench import open_subject, read_ledger, run_diagnose, run_fit

from .conftest import chamber_samples

FIGURES = {"measured_vs_model.png", "residuals.png", "residual_vs_inputs.png",
           "correlations.png", "convergence.png", "ledger.png", "allan.png"}
VOID = {"area", "base", "br", "col", "embed", "hr", "img", "input", "link", "meta", "source",
        "track", "wbr"}


class Page(HTMLParser):
    """Collects images, figures, external references and text; checks the nesting."""

    def __init__(self) -> None:
        super().__init__()
        self.stack: list[str] = []
        self.errors: list[str] = []
        self.imgs: list[dict] = []
        self.refs: list[str] = []
        self.tags: list[str] = []
        self.text: list[str] = []
        self.doctype = ""

    def handle_decl(self, decl):
        self.doctype = decl

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        self.tags.append(tag)
        if tag == "img":
            self.imgs.append(a)
        self.refs += [v for k, v in attrs if k in ("src", "href") and v]
        if tag not in VOID:
            self.stack.append(tag)

    def handle_endtag(self, tag):
        if not self.stack or self.stack[-1] != tag:
            self.errors.append(f"</{tag}> closes <{self.stack[-1] if self.stack else None}>")
        else:
            self.stack.pop()

    def handle_data(self, data):
        self.text.append(data)


def parse(path: Path) -> Page:
    p = Page()
    p.feed(path.read_text(encoding="utf-8"))
    p.close()
    assert not p.errors and not p.stack, (p.errors, p.stack)
    return p


@pytest.fixture(scope="module")
def cli_report(chamber_csv, tmp_path_factory):
    """``gyrostand report CSV --out DIR``: (printed path, out dir)."""
    out = tmp_path_factory.mktemp("cli") / "rep"
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main(["report", str(chamber_csv), "--out", str(out)]) == 0
    return Path(buf.getvalue().strip()), out


def test_cli_writes_a_self_contained_folder_whose_images_are_pngs(cli_report):
    path, out = cli_report
    assert path == out / "report.html" and path.is_file()
    page = parse(path)
    assert page.doctype.lower() == "doctype html"
    assert page.tags[:1] == ["html"] and "title" in page.tags
    assert {"script", "link", "iframe"}.isdisjoint(page.tags)  # nothing to fetch or run
    assert all("://" not in r and not r.startswith("/") for r in page.refs), page.refs
    assert {i["src"] for i in page.imgs} == FIGURES
    assert page.tags.count("figcaption") == len(FIGURES)
    for img in page.imgs:
        png = out / img["src"]
        assert png.is_file(), img["src"]
        assert img["alt"].strip()
        w, h = png_size(png)
        assert (int(img["width"]), int(img["height"])) == (w, h)
        pixels = imread(png)  # decodes the whole PNG
        assert pixels.shape[:2] == (h, w) and w >= 600
        assert pixels[..., :3].std() > 0.05, f"{img['src']} is blank"
    assert {p.name for p in out.iterdir()} == FIGURES | {"report.html"}  # no temp files


def test_page_has_verdict_tables_and_the_missing_effect_first(cli_report, chamber_csv):
    path, _ = cli_report
    html = path.read_text(encoding="utf-8")
    text = " ".join(parse(path).text)
    assert "NOT ADEQUATE" in text
    # the next step names the data as given and gyrostand as invoked (a line to paste)
    assert f"-m gyrostand fit {chamber_csv} --add temp_rate" in text
    for name in ("markov.beta", "temp.gamma", "bias.b", "white.sigma", "markov.sigma"):
        assert f"<code>{name}</code>" in html
    assert "y/(s·°C)" in html
    # candidates ranked: the hidden effect first and marked significant
    assert '<tr class="sig"><td class="l">1. ★ <code>temp_rate</code>' in html
    assert "<td class=\"l\">heating</td>" in html and "<td class=\"l\">soak</td>" in html
    assert "linearised Kalman filter" in text  # convergence: an LKF pass (no run folder)
    assert "has no steps yet" in text
    assert not chamber_csv.with_name("chamber.ledger.jsonl").exists()  # reports only read it


def test_ledger_steps_show_and_a_report_does_not_write_the_ledger(chamber_csv, tmp_path):
    csv = tmp_path / "bench.csv"
    shutil.copy(chamber_csv, csv)
    run_diagnose(open_subject(csv))
    run_fit(open_subject(csv), add=["temp_rate"])
    subject = open_subject(csv)
    ledger = read_ledger(subject.ledger_path)
    path = write_report(subject)
    assert path == default_dir(subject) / "report.html" == tmp_path / "report-bench/report.html"
    assert read_ledger(subject.ledger_path) == ledger
    html = path.read_text(encoding="utf-8")
    text = " ".join(parse(path).text)
    assert "markov,temp,white,bias,temp_rate" in text
    assert "+temp_rate" in text and "diagnose" in text
    assert "linearised Kalman filter" in text  # the LKF carries temp_rate's coefficient
    assert {i["src"] for i in parse(path).imgs} == FIGURES
    assert html.count("<tr>") >= 2 + 5


def test_ledger_points_follow_model_changes():
    class R:  # the parts of a DiagnoseResult that ledger_points reads
        model = Model.parse("markov,temp,bias,temp_rate")
        diagnosis = type("D", (), {"rms": 0.9})()
        fit = type("F", (), {"loglik": -5.0})()
        adequate = True
        significant: list = []

    steps = [
        {"step": 1, "action": "diagnose", "model": ["markov", "temp", "white", "bias"],
         "rms": 1.0, "loglik": -10.0},
        {"step": 2, "action": "fit", "before": {"model": ["markov", "temp", "white", "bias"],
                                                "rms": 1.0, "loglik": -10.0},
         "after": {"model": list(R.model.names), "rms": 0.9, "loglik": -5.0}},
        {"step": 3, "action": "diagnose", "model": list(R.model.names), "rms": 0.9,
         "loglik": -5.0},
    ]
    pts = ledger_points(steps, R())  # type: ignore[arg-type]
    assert [p.label for p in pts] == ["markov,temp,white,bias", "+temp_rate"]
    assert [p.steps for p in pts] == [(1,), (2, 3)]
    assert [p.rms for p in pts] == [1.0, 0.9]


def test_run_folder_convergence_comes_from_the_online_estimates(tmp_path):
    s = chamber_samples(hours=0.5, seed=3)
    run = tmp_path / "run-1"
    (run / "az").mkdir(parents=True)
    t0 = 1.7e9
    Samples.from_arrays(s.t + t0, s.drift, s.temp).to_csv(run / "az" / "samples.csv")
    model = Model.parse("markov,temp,bias")
    (run / "result.json").write_text(json.dumps(
        {"dt": 1.0, "gyros": {"az": {"model": list(model.names), "t0": t0}}}))
    r = lkf(s, model, variant="paper", beta0=0.01, gamma0=-5e-4, b0=0.3,
            held={"markov.sigma": 0.05, "white.sigma": 0.02})
    cols = estimate_columns(["lkf"], model.param_names)
    with (run / "az" / "estimates.csv").open("w") as fh:
        fh.write(",".join(cols) + "\n")
        for k in range(len(s)):
            row = [repr(float(s.t[k] + t0))]
            for p in model.param_names:
                if p in r.history:
                    row += [f"{r.history[p][k]:.9g}", f"{r.history[p + ':std'][k]:.9g}"]
                else:
                    row += [f"{r.value(p):.9g}", "0"]
            fh.write(",".join(row + ["ok"]) + "\n")
    conv = read_estimates(run / "az" / "estimates.csv", t0)
    assert len(conv) == 1 and set(conv[0].values) == {"markov.beta", "temp.gamma", "bias.b"}
    assert set(conv[0].held) == {"markov.sigma", "white.sigma"}
    assert conv[0].t[0] == 0.0 and conv[0].t[-1] == s.t[-1]
    np.testing.assert_allclose(conv[0].values["temp.gamma"], r.history["temp.gamma"],
                               rtol=1e-6)

    path = write_report(open_subject(run))
    assert path == run / "report-az" / "report.html"
    text = " ".join(parse(path).text)
    assert "online estimates (estimates.csv) of its configured model markov,temp,white,bias" in text


def test_envelope_keeps_extremes_and_gaps():
    t = np.arange(100_000.0)
    y = np.zeros_like(t)
    y[12_345], y[77_777] = 5.0, -3.0
    y[40_000:41_000] = np.nan
    tt, yy = envelope(t, y, buckets=500)
    assert tt.size == yy.size == 1000
    assert np.nanmax(yy) == 5.0 and np.nanmin(yy) == -3.0
    assert np.isnan(yy).sum() >= 2 and np.all(np.diff(tt) >= 0)


def test_cli_reports_a_missing_run_as_an_error(tmp_path, capsys):
    assert main(["report", str(tmp_path / "nope")]) == exitcodes.NOINPUT
    assert "error:" in capsys.readouterr().err
