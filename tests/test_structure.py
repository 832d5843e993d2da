"""Structure the redesign won (issue 26), held by walking the package's AST.

- no module over 500 lines;
- no ``from x import _y`` across modules (a name another module needs is that module's
  public API: name it so);
- no import cycle between modules, counting imports inside functions and under
  ``TYPE_CHECKING`` alike (a lazy import up the layers is still an upward import);
- ``gyrostand.core`` imports nothing of the package above it, not even lazily;
- no ``importlib.import_module`` of a package module from inside ``core``.

Run as a script it prints what it finds (``python tests/test_structure.py``).
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent.parent / "gyrostand"
MAX_LINES = 500


def _module_name(path: Path) -> str:
    rel = path.relative_to(PACKAGE.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _modules() -> dict[str, Path]:
    return {_module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


def _is_package(path: Path) -> bool:
    return path.name == "__init__.py"


def _resolve(module: str, path: Path, node: ast.ImportFrom) -> str:
    """The absolute module an ``ImportFrom`` names."""
    if node.level == 0:
        return node.module or ""
    base = module.split(".")
    if not _is_package(path):
        base = base[:-1]
    if node.level > 1:
        base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def _exports(modules: dict[str, Path]) -> dict[str, dict[str, str]]:
    """Package -> its lazy ``EXPORTS`` (name -> absolute defining module)."""
    out: dict[str, dict[str, str]] = {}
    for name, path in modules.items():
        if not _is_package(path):
            continue
        for node in ast.parse(path.read_text(), str(path)).body:
            target = node.target if isinstance(node, ast.AnnAssign) else (
                node.targets[0] if isinstance(node, ast.Assign) else None)
            if isinstance(target, ast.Name) and target.id == "EXPORTS":
                table = ast.literal_eval(node.value)
                out[name] = {k: f"{name}.{v}" for k, v in table.items()}
    return out


def _type_only(tree: ast.AST) -> set[int]:
    """ids of the nodes under ``if TYPE_CHECKING:`` (annotations, not imports at run time)."""
    out: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            out.update(id(n) for stmt in node.body for n in ast.walk(stmt))
    return out


def _imports(modules: dict[str, Path], *, typing: bool = True) -> dict[str, set[str]]:
    """Module -> the package modules it imports (anywhere in its body, in functions too);
    a name imported from a package with lazy ``EXPORTS`` counts as an import of its
    defining module. ``typing=False`` leaves out the imports under ``TYPE_CHECKING``."""
    graph: dict[str, set[str]] = {}
    lazy = _exports(modules)
    for name, path in modules.items():
        tree = ast.parse(path.read_text(), str(path))
        skip = set() if typing else _type_only(tree)
        targets: set[str] = set()
        for node in ast.walk(tree):
            if id(node) in skip:
                continue
            if isinstance(node, ast.Import):
                for alias in node.names:
                    targets.add(alias.name)
            elif isinstance(node, ast.ImportFrom):
                base = _resolve(name, path, node)
                for alias in node.names:
                    sub = f"{base}.{alias.name}"
                    if sub in modules:
                        targets.add(sub)
                    else:
                        targets.add(lazy.get(base, {}).get(alias.name, base))
            elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                  and node.func.attr == "import_module" and node.args
                  and isinstance(node.args[0], ast.Constant)
                  and isinstance(node.args[0].value, str)):
                target = node.args[0].value
                if target.startswith("."):
                    continue  # a package's own lazy export (PEP 562), checked below
                targets.add(target)
        graph[name] = {t for t in targets if t in modules and t != name}
    return graph


def private_imports(modules: dict[str, Path] | None = None) -> list[str]:
    """``from x import _y`` where x is another module of the package."""
    modules = modules or _modules()
    found = []
    for name, path in modules.items():
        tree = ast.parse(path.read_text(), str(path))
        for node in ast.walk(tree):
            if not isinstance(node, ast.ImportFrom):
                continue
            base = _resolve(name, path, node)
            if not base.startswith("gyrostand") or base == name:
                continue
            for alias in node.names:
                if alias.name.startswith("_") and not alias.name.startswith("__"):
                    found.append(f"{name}:{node.lineno} from {base} import {alias.name}")
    return found


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan).

    A package's ``__init__`` that re-exports its submodules is not an edge back: the
    import of ``a.b`` from ``a`` is the package assembling itself, so edges from a package
    to its own submodules are left out.
    """
    edges = {m: {t for t in ts if not t.startswith(m + ".")} for m, ts in graph.items()}
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []
    counter = [0]
    sys.setrecursionlimit(10000)

    def visit(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in edges.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    return out


def long_modules(modules: dict[str, Path] | None = None) -> list[str]:
    modules = modules or _modules()
    return [f"{n} ({len(p.read_text().splitlines())} lines)" for n, p in modules.items()
            if len(p.read_text().splitlines()) > MAX_LINES]


#: below every layer: the exception tree (it imports nothing of the package)
FOUNDATION = ("gyrostand", "gyrostand.errors")


def upward_from_core(graph: dict[str, set[str]]) -> list[str]:
    return sorted(f"{m} -> {t}" for m, ts in graph.items() if m.startswith("gyrostand.core")
                  for t in ts if not t.startswith("gyrostand.core") and t not in FOUNDATION)


def test_no_module_over_500_lines():
    assert long_modules() == []


def test_no_private_imports_across_modules():
    assert private_imports() == []


def test_no_import_cycles():
    """Counting every import a module runs, at its top or in a function; the imports
    under ``TYPE_CHECKING`` are annotations and may point back (they still count for the
    layers: core may not name anything above it even there)."""
    assert cycles(_imports(_modules(), typing=False)) == []


def test_core_imports_nothing_above_it():
    assert upward_from_core(_imports(_modules())) == []


def test_the_checks_can_fail(tmp_path):
    """The walker sees a lazy import cycle and a private import (a check that cannot fail
    is a defect)."""
    pkg = tmp_path / "gyrostand"
    (pkg / "core").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "core" / "__init__.py").write_text("")
    (pkg / "core" / "a.py").write_text("def f():\n    from .b import _g\n    return _g\n")
    (pkg / "core" / "b.py").write_text(
        "def _g():\n    from gyrostand.core import a\n    return a\n"
        "def h():\n    import importlib\n    return importlib.import_module('gyrostand.render')\n")
    (pkg / "render.py").write_text("x = 1\n" * (MAX_LINES + 1))
    global PACKAGE
    saved, PACKAGE = PACKAGE, pkg
    try:
        mods = _modules()
        graph = _imports(mods)
        assert cycles(_imports(mods, typing=False)) == [["gyrostand.core.a", "gyrostand.core.b"]]
        assert private_imports(mods) == ["gyrostand.core.a:2 from gyrostand.core.b import _g"]
        assert upward_from_core(graph) == ["gyrostand.core.b -> gyrostand.render"]
        assert long_modules(mods) == [f"gyrostand.render ({MAX_LINES + 1} lines)"]
    finally:
        PACKAGE = saved


if __name__ == "__main__":
    mods = _modules()
    g = _imports(mods)
    print("long modules:", *long_modules(mods), sep="\n  ")
    print("private imports:", *private_imports(mods), sep="\n  ")
    print("upward from core:", *upward_from_core(g), sep="\n  ")
    print("cycles:")
    for c in cycles(_imports(mods, typing=False)):
        print("  ", len(c), c)
