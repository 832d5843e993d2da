"""python-can is used through its public API only (issue 27), held by walking the AST of
the package, the tests and the benchmarks:

- no ``from can... import _x`` and no import of a ``can._x`` module;
- no ``can..._x`` attribute of the ``can`` package itself (``can.io.blf._x``);
- no ``obj._x`` on an object a python-can call made (``r = blf.BLFReader(p)``,
  ``with can.Bus() as bus``, in the same module);
- no ``obj._x`` whose name is a private name python-can defines (a method, a class
  attribute or an instance attribute it assigns, found by walking python-can's own
  source) unless our code defines that name itself: a subclass calling
  ``self._flush()``, or ``writer._write_header(...)`` on a ``can.BLFWriter``.

:data:`KNOWN` lists the uses left on purpose, each with its reason; the test fails on any
other, and on a listed one that is gone (the list only shrinks).

A private name is one underscore then a letter (not a dunder). Run as a script it prints
what it finds (``python tests/test_no_private_can.py``).
"""

from __future__ import annotations

import ast
from collections.abc import Iterable
from pathlib import Path

import can

ROOT = Path(__file__).resolve().parent.parent
SCANNED = ("gyrostand", "tests", "benchmarks")

#: uses left on purpose: ``file: (private names, why)``
KNOWN: dict[str, tuple[frozenset[str], str]] = {
    "gyrostand/can/logs/read.py": (
        frozenset({"_parse_container", "_tail", "_pos"}),
        "the damage-tolerant BLF reader drives python-can's container parser one "
        "container at a time (its public iterator ends the file at the first damage); "
        "the alternative is a copy of that parser"),
    "tests/can/test_blfarray.py": (
        frozenset({"_parse_container", "_tail"}),
        "python-can's own container parser is the oracle the array parser is held to"),
    "tests/can/test_can_decode_bin.py": (
        frozenset({"_on_error"}),
        "what the Notifier calls on a bus error, called as the Notifier does"),
}


def _private(name: str) -> bool:
    return name.startswith("_") and not name.startswith("__") and len(name) > 1


def _defined(files: Iterable[Path]) -> set[str]:
    """The private names the files define: functions and methods, class-level and
    module-level assignments, and ``self._x = ...`` attributes."""
    out: set[str] = set()
    for path in files:
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
                names = [node.name]
            elif isinstance(node, ast.Assign | ast.AnnAssign | ast.AugAssign):
                # a name, or an attribute of self/cls (not ``other._x = ...``)
                targets = node.targets if isinstance(node, ast.Assign) else [node.target]
                names = [n.id if isinstance(n, ast.Name) else n.attr
                         for t in targets for n in ast.walk(t)
                         if isinstance(n, ast.Name) or (
                             isinstance(n, ast.Attribute) and isinstance(n.value, ast.Name)
                             and n.value.id in ("self", "cls"))]
            else:
                continue
            out.update(n for n in names if _private(n))
    return out


def can_private_names() -> set[str]:
    """Every private name python-can's source defines."""
    return _defined(sorted(Path(can.__file__).parent.rglob("*.py")))


def _dotted(node: ast.expr) -> str | None:
    parts = []
    while isinstance(node, ast.Attribute):
        parts.append(node.attr)
        node = node.value
    if isinstance(node, ast.Name):
        return ".".join([node.id, *reversed(parts)])
    return None


def _is_can(module: str) -> bool:
    return module == "can" or module.startswith("can.")


def _can_names(tree: ast.AST) -> tuple[set[str], set[str]]:
    """The module's names bound to python-can (``import can``, ``from can.io import blf``,
    ``from can import Bus``) and the names it binds to what a call of one of them returns
    (``reader = blf.BLFReader(p)``, ``with can.Bus() as bus``)."""
    aliases: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            aliases.update((a.asname or a.name).split(".")[0] for a in node.names
                           if _is_can(a.name))
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and _is_can(
                node.module or ""):
            aliases.update(a.asname or a.name for a in node.names)

    def made_by_can(value: ast.expr | None) -> bool:
        if not isinstance(value, ast.Call):
            return False
        dotted = _dotted(value.func)
        return dotted is not None and dotted.split(".")[0] in aliases

    objects: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Assign) and made_by_can(node.value):
            objects.update(t.id for t in node.targets if isinstance(t, ast.Name))
        elif isinstance(node, ast.With | ast.AsyncWith):
            objects.update(i.optional_vars.id for i in node.items
                           if isinstance(i.optional_vars, ast.Name)
                           and made_by_can(i.context_expr))
    return aliases, objects


def private_can_uses(files: list[Path] | None = None, root: Path = ROOT) -> list[str]:
    """``file:line what`` for each use of a python-can private name in ``files``."""
    if files is None:
        files = [p for d in SCANNED for p in sorted((root / d).rglob("*.py"))]
    ours = _defined(files)
    theirs = can_private_names() - ours
    out = []
    for path in files:
        tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
        where = path.relative_to(root).as_posix()
        _, objects = _can_names(tree)
        for node in ast.walk(tree):
            found = None
            if isinstance(node, ast.ImportFrom) and node.level == 0 and _is_can(
                    node.module or ""):
                bad = [a.name for a in node.names if _private(a.name)]
                if bad or any(_private(p) for p in (node.module or "").split(".")):
                    found = f"from {node.module} import {', '.join(bad or ['...'])}"
            elif isinstance(node, ast.Import):
                bad = [a.name for a in node.names if _is_can(a.name)
                       and any(_private(p) for p in a.name.split("."))]
                found = f"import {', '.join(bad)}" if bad else None
            elif isinstance(node, ast.Attribute) and _private(node.attr):
                dotted = _dotted(node)
                if dotted is not None and _is_can(dotted.split(".", 1)[0]):
                    found = dotted
                elif isinstance(node.value, ast.Name) and node.value.id in objects:
                    found = f"{ast.unparse(node)} (a python-can object's private {node.attr})"
                elif node.attr in theirs:
                    found = f"{ast.unparse(node)} (python-can's private {node.attr})"
            if found:
                out.append(f"{where}:{node.lineno} {found}")
    return sorted(out)


def unexpected(uses: list[str]) -> tuple[list[str], list[str]]:
    """The uses :data:`KNOWN` does not list, and the listed names no longer used."""
    seen: dict[str, set[str]] = {}
    new = []
    for use in uses:
        where = use.split(":", 1)[0]
        name = next((n for n in KNOWN.get(where, (frozenset(), ""))[0]
                     if f"._{n[1:]} " in use + " " or use.endswith(f"._{n[1:]}")
                     or f"private {n})" in use), None)
        if name is None:
            new.append(use)
        else:
            seen.setdefault(where, set()).add(name)
    gone = [f"{w}: {n}" for w, (names, _) in KNOWN.items() for n in sorted(names)
            if n not in seen.get(w, set())]
    return new, gone


def test_no_private_python_can_use():
    new, gone = unexpected(private_can_uses())
    assert new == [], "python-can's private API used (use its public API)"
    assert gone == [], "no longer used: take it off KNOWN"


def test_the_check_can_fail(tmp_path):
    """The walker sees a subclass calling python-can's private methods, a private import
    and a private module attribute (a check that cannot fail is a defect)."""
    bad = tmp_path / "gyrostand" / "bad.py"
    bad.parent.mkdir()
    bad.write_text(
        "import can\n"
        "from can.io.blf import _flush_thing, BLFWriter\n"
        "import can._private_mod\n"
        "class W(can.BLFWriter):\n"
        "    def flush(self):\n"
        "        self._flush()\n"
        "        self._write_header(0)\n"
        "        self._ours()\n"
        "    def _ours(self):\n"
        "        r = can.LogReader('x.blf')\n"
        "        r._pos = 0\n"
        "        return can.io.blf._secret\n")
    assert {"_flush", "_write_header", "_buffer"} <= can_private_names()
    assert private_can_uses([bad], tmp_path) == [
        "gyrostand/bad.py:11 r._pos (a python-can object's private _pos)",
        "gyrostand/bad.py:12 can.io.blf._secret",
        "gyrostand/bad.py:2 from can.io.blf import _flush_thing",
        "gyrostand/bad.py:3 import can._private_mod",
        "gyrostand/bad.py:6 self._flush (python-can's private _flush)",
        "gyrostand/bad.py:7 self._write_header (python-can's private _write_header)",
    ]


if __name__ == "__main__":
    uses = private_can_uses()
    print("python-can private uses:", *uses, sep="\n  ")
    print("not in KNOWN:", *unexpected(uses)[0], sep="\n  ")
