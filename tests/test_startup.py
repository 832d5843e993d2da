"""Start-up: the command line imports what a command uses, when it uses it.

Each check runs in a fresh interpreter (a subprocess) and looks at ``sys.modules`` there:
building the argument parser and printing every help page must not import the numerical
core's heavy dependencies, and ``identify`` must not import those it does not use.
"""

import json
import subprocess
import sys
from pathlib import Path

import pytest

from gyrostand.core import aot
from gyrostand.core.model import Model
from gyrostand.core.names import METHODS, VOCABULARY
from gyrostand.core.profiles import paper_profile
from gyrostand.core.registry import REGISTRY
from gyrostand.core.simulation import simulate
from gyrostand.core.terms.builtin import TERMS

from .conftest import truth

#: what none of the help pages needs (numba: 0.15 s, scipy.stats: 0.5 s, cantools + can:
#: 0.9 s with asammdf, matplotlib: 0.3 s, on the 2-core test machine)
HEAVY = ("numpy", "scipy", "scipy.stats", "scipy.signal", "numba", "matplotlib", "cantools",
         "can", "yaml", "gyrostand.config", "gyrostand.session")

REPORT = ("import json, sys\n"
          "print(json.dumps(sorted(m for m in sys.modules if m in {heavy!r})))\n")


def loaded_after(code: str, heavy: tuple[str, ...] = HEAVY) -> list[str]:
    """The modules of ``heavy`` imported by ``code`` in a fresh interpreter."""
    out = subprocess.run([sys.executable, "-c", code + "\n" + REPORT.format(heavy=set(heavy))],
                         capture_output=True, text=True, timeout=300, check=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def test_building_the_parser_and_every_help_page_imports_nothing_heavy():
    code = ("import contextlib, io\n"
            "from gyrostand.cli import build_parser, main\n"
            "parser = build_parser()\n"
            "sub = next(a for a in parser._actions if a.dest == 'command')\n"
            "for argv in [['--help']] + [[name, '--help'] for name in sub.choices]:\n"
            "    with contextlib.redirect_stdout(io.StringIO()) as f:\n"
            "        try:\n"
            "            main(argv)\n"
            "        except SystemExit as e:\n"
            "            assert e.code == 0, argv\n"
            "    assert 'usage: gyrostand' in f.getvalue(), argv\n"
            "assert len(sub.choices) >= 11, sorted(sub.choices)\n")
    assert loaded_after(code) == []


def test_gyrostand_help_as_a_process_imports_nothing_heavy():
    code = ("import runpy, sys\n"
            "sys.argv = ['gyrostand', '--help']\n"
            "try:\n"
            "    runpy.run_module('gyrostand', run_name='__main__')\n"
            "except SystemExit as e:\n"
            "    assert e.code == 0\n")
    assert loaded_after(code) == []


def test_importing_the_core_package_is_lazy():
    assert loaded_after("import gyrostand.core, gyrostand.core.names") == []


@pytest.fixture(scope="module")
def csv_path(tmp_path_factory):
    m = Model.parse("markov,temp,bias")
    s = simulate(m, truth("C1", sigma_v=0.01, **{"bias.b": 0.3}), paper_profile(), seed=52)
    p = tmp_path_factory.mktemp("startup") / "samples.csv"
    s.to_csv(p)
    return p


def test_identify_ml_imports_neither_scipy_stats_nor_can_nor_matplotlib(csv_path):
    code = ("import contextlib, io, json\n"
            "from gyrostand.cli import main\n"
            "with contextlib.redirect_stdout(io.StringIO()) as f:\n"
            f"    assert main(['identify', {str(csv_path)!r}, '--method', 'ml', '--json']) == 0\n"
            "assert json.loads(f.getvalue())['method'] == 'ml'\n")
    heavy = ("scipy.stats", "scipy.signal", "matplotlib", "cantools", "can",
             "gyrostand.config", "gyrostand.session", "numba", "gyrostand.core.kalman")
    # the fit's Kalman filter; numba only where the kernels were not compiled at install
    # (gyrostand.core.aot: then its dispatchers are made on first need)
    numba = [] if aot.built() is not None else ["numba"]
    assert loaded_after(code, heavy) == sorted(["gyrostand.core.kalman", *numba])


def test_the_core_package_exports_what_it_did():
    """``from gyrostand.core import X`` (and ``from gyrostand.core.SUB import X`` for each
    subpackage) gives the object its module defines, whichever is imported first; the
    identifiers' functions are their subpackages' (``gyrostand.core.ml.ml``)."""
    code = ("import importlib, types\n"
            "import gyrostand.core.ml.fit, gyrostand.core.lkf.filter, gyrostand.core.lsq.fit\n"
            "from gyrostand.core.ml import ml\n"
            "from gyrostand.core.lkf import lkf\n"
            "from gyrostand.core.lsq import lsq\n"
            "from gyrostand.core.diagnose import diagnose\n"
            "from gyrostand.core import identify, simulate\n"
            "for f in (identify, lkf, lsq, ml, simulate, diagnose):\n"
            "    assert isinstance(f, types.FunctionType), f\n"
            "for pkg in ('gyrostand.core', 'gyrostand.core.ml', 'gyrostand.core.lkf',\n"
            "            'gyrostand.core.lsq', 'gyrostand.core.diagnose',\n"
            "            'gyrostand.core.design', 'gyrostand.core.terms'):\n"
            "    p = importlib.import_module(pkg)\n"
            "    for name, source in p.EXPORTS.items():\n"
            "        src = importlib.import_module(pkg + '.' + source)\n"
            "        assert getattr(p, name) is getattr(src, name), (pkg, name)\n"
            "    assert set(p.__all__) <= set(dir(p))\n"
            "core = importlib.import_module('gyrostand.core')\n"
            "try:\n"
            "    core.no_such_name\n"
            "except AttributeError as e:\n"
            "    assert 'no_such_name' in str(e)\n"
            "else:\n"
            "    raise AssertionError('no AttributeError')\n")
    # every export was imported: the kernels' modules among them
    assert "gyrostand.core.kalman" in loaded_after(code, (*HEAVY, "gyrostand.core.kalman"))


def test_the_light_names_are_the_core_s_names():
    assert VOCABULARY == tuple(TERMS)  # same names, same (PRODUCT.md) order
    assert sorted(METHODS) == sorted(REGISTRY)


def test_replay_of_a_blf_imports_python_can_without_asammdf(tmp_path):
    """python-can's MF4 support (asammdf, pandas: ~0.5 s) stays off a BLF replay's import
    path; the replay still ends in a run folder, and asammdf is importable afterwards."""
    root = Path(__file__).resolve().parents[1]
    argv = ["-q", "replay", str(root / "configs" / "demo.yaml"),
            str(root / "tests" / "data" / "runfolder" / "replay.blf"), "--out", str(tmp_path)]
    code = ("import contextlib, io\n"
            "from gyrostand.cli import main\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n"
            f"    assert main({argv!r}) == 0\n"
            "import sys\n"
            "heavy_before = sorted(m for m in ('can', 'asammdf', 'pandas') if m in sys.modules)\n"
            "assert heavy_before == ['can'], heavy_before\n"
            "import asammdf\n")
    assert loaded_after(code, ("can", "asammdf", "pandas", "cantools")) == \
        ["asammdf", "can", "cantools", "pandas"]
    assert len(list(tmp_path.glob("*/*/samples.csv"))) == 1
