"""Text and JSON outputs stay byte-identical to the ones main printed before the renderers
became one package (golden files made by ``make_golden.py``); the HTML report keeps every
number and every figure it showed."""

from __future__ import annotations

import html
import re
from collections import Counter

import pytest

from .make_golden import COMMANDS, GOLDEN, outputs

NAMES = [*COMMANDS, "replay_report.txt"]


@pytest.fixture(scope="module")
def made(tmp_path_factory) -> dict[str, str]:
    return outputs(tmp_path_factory.mktemp("golden"))


@pytest.mark.parametrize("name", NAMES)
def test_output_is_byte_identical_to_the_golden_file(made, name):
    assert made[name] == (GOLDEN / name).read_text(), f"{name} differs from golden/{name}"


def shown(page: str) -> tuple[Counter[str], set[str]]:
    """The numbers a page shows (its text, tags and CSS left out) and the images it links."""
    images = set(re.findall(r'<img src="([^"]+)"', page))
    body = re.sub(r"<style>.*?</style>", " ", page, flags=re.S)
    text = html.unescape(re.sub(r"<[^>]+>", " ", body))
    return Counter(re.findall(r"[−-]?\d+(?:\.\d+)?(?:e[−+-]?\d+)?", text)), images


def test_the_html_report_keeps_every_number_and_figure(made):
    want_numbers, want_images = shown((GOLDEN / "report.html").read_text())
    got_numbers, got_images = shown(made["report.html"])
    assert len(want_images) == 7 and want_images <= got_images
    missing = want_numbers - got_numbers
    assert not missing, f"numbers of the old report missing from the new: {dict(missing)}"
