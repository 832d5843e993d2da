"""README.md stays an introduction: at most 250 lines, the test command CI runs after its
marker, and every relative link pointing at a file (or folder) of the repository.

The details live in the documentation site (docs/, mkdocs.yml); .ci/run reads the line
after ``<!-- test-command -->`` and runs it, so that line must be a command.
"""

from __future__ import annotations

import re
from pathlib import Path
from urllib.parse import unquote

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
MAX_LINES = 250
MARKER = "<!-- test-command -->"

#: inline links and images ``[text](target)`` / ``![alt](target "title")``
INLINE_LINK = re.compile(r"!?\[[^\]]*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
#: reference definitions ``[label]: target``
REFERENCE_DEF = re.compile(r"^\s{0,3}\[[^\]]+\]:\s*<?(\S+?)>?(?:\s+.*)?$", re.MULTILINE)
#: anything with a scheme (https:, mailto:, file:) or protocol-relative, or a pure anchor
EXTERNAL = re.compile(r"^(?:[a-zA-Z][a-zA-Z0-9+.-]*:|//|#)")


def _text() -> str:
    return README.read_text(encoding="utf-8")


def _without_code(text: str) -> str:
    """The README without fenced code blocks, indented code blocks and code spans, where a
    bracket is not a link."""
    text = re.sub(r"^(```|~~~).*?^\1", "", text, flags=re.MULTILINE | re.DOTALL)
    text = re.sub(r"^(?: {4}|\t).*$", "", text, flags=re.MULTILINE)
    return re.sub(r"`[^`\n]*`", "", text)


def relative_links(text: str) -> list[str]:
    prose = _without_code(text)
    targets = INLINE_LINK.findall(prose) + REFERENCE_DEF.findall(prose)
    return [t for t in targets if not EXTERNAL.match(t)]


def test_readme_is_at_most_250_lines() -> None:
    n = len(_text().splitlines())
    assert n <= MAX_LINES, f"README.md has {n} lines (at most {MAX_LINES}): move details to docs/"


def test_readme_has_the_test_command_after_its_marker() -> None:
    lines = _text().splitlines()
    assert lines.count(MARKER) == 1, f"README.md must hold the line {MARKER!r} exactly once"
    i = lines.index(MARKER)
    assert i + 1 < len(lines), "the test-command marker is the last line"
    command = lines[i + 1].strip()
    # as .ci/run reads it: the next line, leading blanks removed, run as written
    assert command, "the line after the test-command marker is empty"
    assert not command.startswith(("<!--", "#", "```")), f"not a command: {command!r}"
    assert "pytest" in command, f"the test command does not run pytest: {command!r}"


def test_every_relative_link_in_readme_exists() -> None:
    links = relative_links(_text())
    assert links, "README.md links nowhere (it should point at the docs)"
    missing = []
    for target in links:
        path = unquote(target.split("#", 1)[0].split("?", 1)[0])
        if not path:
            continue
        if not (README.parent / path).exists():
            missing.append(target)
    assert not missing, f"README.md links to files that do not exist: {missing}"


def test_the_link_finder_sees_links_and_skips_code() -> None:
    text = (
        "See [the docs](docs/index.md#top) and ![a](img/x.png \"t\") and [web](https://x.org).\n"
        "[ref]: CHANGELOG.md\n"
        "`[not](a/link.md)`\n"
        "    [indented](code/block.md)\n"
        "```\n[fenced](no/link.md)\n```\n"
        "[anchor](#section)\n"
    )
    assert relative_links(text) == ["docs/index.md#top", "img/x.png", "CHANGELOG.md"]
