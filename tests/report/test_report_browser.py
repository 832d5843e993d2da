"""The report opened in a real headless Chromium: every plot image loads.

A copy of the page gets a script that, on the window's ``load`` event, writes each
image's ``naturalWidth``/``naturalHeight`` into the DOM; ``chromium --dump-dom`` prints
the DOM after loading. An image that is missing or not decodable has naturalWidth 0.
Chromium comes from Debian's packages (``.ci/run`` installs it when it is missing).
"""

import contextlib
import io
import re
import shutil
import subprocess
from pathlib import Path

import pytest

from gyrostand.cli import main
from gyrostand.report.page import png_size

from .test_report import FIGURES, parse

CHROMIUM = next((p for p in (shutil.which("chromium"), "/usr/bin/chromium")
                 if p and Path(p).exists()), None)
pytestmark = pytest.mark.skipif(
    CHROMIUM is None, reason="Chromium is not installed (apt-get install chromium; .ci/run "
                             "installs it)")

PROBE = """<script>
window.addEventListener("load", function () {
  var rows = [];
  document.querySelectorAll("img").forEach(function (im) {
    rows.push(im.getAttribute("src") + " " + im.naturalWidth + " " + im.naturalHeight);
  });
  var pre = document.createElement("pre");
  pre.id = "image-check";
  pre.textContent = rows.join("\\n");
  document.body.appendChild(pre);
});
</script>
"""


def loaded_image_sizes(page: Path, profile: Path) -> dict[str, tuple[int, int]]:
    """Open ``page`` in headless Chromium; ``src -> (naturalWidth, naturalHeight)``."""
    html = page.read_text(encoding="utf-8")
    assert html.count("</body>") == 1
    page.write_text(html.replace("</body>", PROBE + "</body>"), encoding="utf-8")
    cmd = [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
           "--no-first-run", "--disable-background-networking", "--disable-component-update",
           "--disable-sync", "--disable-dev-shm-usage", f"--user-data-dir={profile}",
           "--dump-dom", page.resolve().as_uri()]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=120, check=False)
    m = re.search(r'<pre id="image-check">(.*?)</pre>', done.stdout, re.S)
    assert m, f"the probe did not run (exit {done.returncode}): {done.stderr[-2000:]}"
    out = {}
    for line in m.group(1).strip().splitlines():
        src, w, h = line.rsplit(" ", 2)
        out[src] = (int(w), int(h))
    return out


@pytest.fixture(scope="module")
def report_dir(chamber_csv, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("browser") / "rep"
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["report", str(chamber_csv), "--out", str(out)]) == 0
    return out


def test_every_plot_image_loads_in_chromium(report_dir, tmp_path):
    copy = tmp_path / "copy"
    shutil.copytree(report_dir, copy)
    srcs = [i["src"] for i in parse(copy / "report.html").imgs]
    assert set(srcs) == FIGURES
    sizes = loaded_image_sizes(copy / "report.html", tmp_path / "profile")
    assert sorted(sizes) == sorted(srcs)
    for src in srcs:
        assert sizes[src][0] > 0, f"{src} did not load in the browser"
        assert sizes[src] == png_size(copy / src)


def test_the_browser_check_catches_a_missing_and_a_broken_image(report_dir, tmp_path):
    copy = tmp_path / "copy"
    shutil.copytree(report_dir, copy)
    (copy / "allan.png").unlink()
    (copy / "ledger.png").write_bytes(b"\x89PNG\r\n\x1a\n not really a png")
    sizes = loaded_image_sizes(copy / "report.html", tmp_path / "profile")
    assert sizes["allan.png"][0] == 0 and sizes["ledger.png"][0] == 0
    assert all(sizes[s][0] > 0 for s in FIGURES - {"allan.png", "ledger.png"})
