"""The examples in the core's docstrings run (STYLE: examples in docstrings run).

A module listed in :data:`WITH_EXAMPLES` must have examples, and every one must run and
pass: a module whose examples vanished (or were never found, e.g. behind a decorator that
hides the docstring) fails instead of passing on zero examples. Every other core module's
examples, if it has any, run too (a module that gains examples belongs in the list).
"""

import doctest
import importlib
import pkgutil

import pytest

import gyrostand.core

CORE = ["gyrostand.core"] + [m.name for m in pkgutil.walk_packages(gyrostand.core.__path__,
                                                                   "gyrostand.core.")]

#: the modules whose docstrings carry runnable examples: each must run at least one
WITH_EXAMPLES = ["gyrostand.core", "gyrostand.core.diagnose.allan", "gyrostand.core.registry",
                 "gyrostand.core.model", "gyrostand.core.profiles", "gyrostand.core.results",
                 "gyrostand.core.simulation", "gyrostand.core.summary"]


def _run(name: str) -> doctest.TestResults:
    return doctest.testmod(importlib.import_module(name), optionflags=doctest.ELLIPSIS)


@pytest.mark.parametrize("name", WITH_EXAMPLES)
def test_docstring_examples_ran_and_passed(name):
    result = _run(name)
    assert result.attempted > 0, f"{name}: no docstring example ran"
    assert result.failed == 0, f"{result.failed} docstring example(s) failed in {name}"


@pytest.mark.parametrize("name", [m for m in CORE if m not in WITH_EXAMPLES])
def test_other_modules_examples_pass_if_any(name):
    result = _run(name)
    assert result.failed == 0, f"{result.failed} docstring example(s) failed in {name}"


def test_the_modules_with_examples_are_core_modules():
    assert set(WITH_EXAMPLES) <= set(CORE), set(WITH_EXAMPLES) - set(CORE)
