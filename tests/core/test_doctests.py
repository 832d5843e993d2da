"""The examples in the core's docstrings run (STYLE: examples in docstrings run)."""

import doctest
import importlib
import pkgutil

import pytest

import gyrostand.core

MODULES = ["gyrostand.core"] + [f"gyrostand.core.{m.name}"
                                for m in pkgutil.iter_modules(gyrostand.core.__path__)]


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name):
    result = doctest.testmod(importlib.import_module(name), optionflags=doctest.ELLIPSIS)
    assert result.failed == 0, f"{result.failed} docstring example(s) failed in {name}"
