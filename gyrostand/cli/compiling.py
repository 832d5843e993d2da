"""What numba compiles while a command runs (issue 25): each first-use compilation of a
kernel as a progress stage (``numba: compiling kf_run (first use; cached in DIR)``), and
the demo's count of them. Kernels compile once per install (then load from the cache
:func:`gyrostand.core.jit.cache_dir` names), so after the first run nothing shows."""

from __future__ import annotations

import time
from typing import Any

from .. import progress
from ..core import aot, jit

__all__ = ["CompileClock", "show_compilations"]


_shown: list[bool] = []


def show_compilations() -> None:
    """From now on in this process, each kernel's compilation is a progress stage (a bar
    on a terminal; nothing with ``-q`` or when progress is off). Once per process."""
    if _shown:
        return
    _shown.append(True)
    open_stages: list[progress.Stage] = []

    def on_compile(kernel: str, started: bool) -> None:
        if started:
            open_stages.append(progress.Stage(
                "numba", f"compiling {kernel} (first use; cached in {jit.cache_dir()})",
                None, ""))
        elif open_stages:
            open_stages.pop().close()

    jit.watch(on_compile)


class CompileClock:
    """Wall time numba spends compiling in this process (numba reports a compilation on a
    cache miss only: a kernel loaded from its cache costs nothing here), the outermost
    compile of nested ones counted once."""

    def __init__(self) -> None:
        self.kernels = 0
        self.seconds = 0.0
        self.names: list[str] = []
        self._t0 = 0.0
        self._unwatch: Any = None

    def _on_compile(self, kernel: str, started: bool) -> None:
        if started:
            self._t0 = time.perf_counter()
            if kernel not in self.names:
                self.names.append(kernel)
        else:
            self.kernels += 1
            self.seconds += time.perf_counter() - self._t0

    def __enter__(self) -> CompileClock:
        jit.listen()
        self._unwatch = jit.watch(self._on_compile)
        return self

    def __exit__(self, *exc: object) -> None:
        self._unwatch()

    def line(self) -> str:
        if not self.kernels:
            if aot.built() is not None:
                return ("numba: nothing compiled (the kernels were compiled at install, "
                        "gyrostand.core._kernels)")
            return "numba: every kernel loaded from its cache (nothing compiled)"
        names = ", ".join(self.names[:6]) + (", ..." if len(self.names) > 6 else "")
        return (f"numba: first run: {self.kernels} kernel compilation(s) in "
                f"{self.seconds:.1f} s ({names}; cached in {jit.cache_dir()}: later runs "
                f"and commands load them)")
