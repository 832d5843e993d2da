"""The build's one step beyond pyproject.toml: numba's kernels compiled ahead of time into
the extension module ``gyrostand.core._kernels`` (:mod:`gyrostand.core.aot`), so that the
first run after an install compiles nothing (issue 25). Without a C compiler, or where
numba's ahead-of-time compiler fails, the build says so and goes on: the kernels then
compile on first use, as before."""

from __future__ import annotations

import sys
from pathlib import Path

from setuptools import setup
from setuptools.command.build_ext import build_ext
from setuptools.dist import Distribution

ROOT = Path(__file__).resolve().parent


class BuildKernels(build_ext):
    """``build_ext`` that builds the kernels' module (in place for an editable install)."""

    def run(self) -> None:
        super().run()
        out = (ROOT if self.inplace else Path(self.build_lib)) / "gyrostand" / "core"
        out.mkdir(parents=True, exist_ok=True)
        sys.path.insert(0, str(ROOT))
        try:
            from gyrostand.core import aot

            built = aot.build(out)
            print(f"gyrostand: kernels compiled ahead of time into {built}")
        except Exception as exc:  # noqa: BLE001 - the package works without them
            print(f"gyrostand: WARNING: kernels not compiled ahead of time "
                  f"({type(exc).__name__}: {exc}); they compile on first use instead",
                  file=sys.stderr)
        finally:
            sys.path.remove(str(ROOT))


class WithKernels(Distribution):
    """A distribution with a compiled module (its wheel is tagged for the platform)."""

    def has_ext_modules(self) -> bool:
        return True


setup(cmdclass={"build_ext": BuildKernels}, distclass=WithKernels)
