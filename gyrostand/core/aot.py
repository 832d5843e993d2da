"""The kernels compiled ahead of time, at install (issue 25: a first run that is not a wait).

numba compiles each kernel on its first call (:mod:`.jit`): about 6 s of CPU for
``diagnose``'s five on an empty cache, on a 3-s command. ``pip install`` now also builds
them into an extension module, ``gyrostand.core._kernels`` (numba's ahead-of-time
compiler, :mod:`numba.pycc`, run by ``setup.py``'s ``build_ext``), from the same Python
source and for the argument types the commands pass (:data:`SPECS`). A process imports
it (a few ms) instead of compiling or loading from numba's cache, whatever
``NUMBA_CACHE_DIR`` says.

The module is used only while it matches the source it was built from: it carries the
hash of the kernels' source files (:func:`source_key`), and :func:`kernel` gives the
numba dispatcher instead when the hash differs (an edited kernel in a development tree,
before ``pip install -e .`` runs again), when the module is missing (no C compiler at
install: the build says so and goes on) or when ``GYROSTAND_KERNELS=jit`` asks for numba
(the benchmark's comparison, a kernel being debugged). Both give the same numbers to the
bit (tests/core/test_aot.py): the same LLVM code from the same source, without fast-math.

The exported functions release the GIL, as the ``nogil`` dispatchers do: the candidates'
refits run on two threads.
"""

from __future__ import annotations

import hashlib
import importlib
import logging
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

__all__ = ["FALLBACKS", "MODULE", "SPECS", "build", "built", "kernel", "signature",
           "source_key"]

#: the extension module's name
MODULE = "gyrostand.core._kernels"

_HERE = Path(__file__).resolve().parent

_A1, _A2, _A3 = "f8[::1]", "f8[:, ::1]", "f8[:, :, ::1]"
#: an argument's type -> the rank of the array it is (0: a scalar)
_RANK = {"f8": 0, "i8": 0, "b1": 0, _A1: 1, _A2: 2, _A3: 3}

#: exported name -> (module, function, return type, argument types): the types every
#: caller passes (C-contiguous writable float64 arrays, :func:`~.rts.writable`; the work
#: arrays of ``kf_work``, ``forward_work``, ``backward_work``, ``score_work``)
SPECS: dict[str, tuple[str, str, str, tuple[str, ...]]] = {
    "kf_run": ("gyrostand.core.kalman", "_kf_run", f"Tuple(({_A2}, {_A1}, {_A2}, f8, i8))", (
        _A1, _A1, _A1, "f8", _A1, _A2, "b1",
        _A2, _A2, _A2, _A1, _A2, _A1, _A1, _A1, _A2, _A1, _A1, _A2, _A2, _A2)),
    "first_order_response": ("gyrostand.core.kalman", "_first_order_response", _A1, (
        _A1, "f8", "f8", "f8", "f8", _A1)),
    "rts_forward": ("gyrostand.core.rts", "rts_forward",
                    f"Tuple(({_A2}, {_A3}, {_A2}, {_A3}))", (
                        _A1, _A1, _A1, "f8", _A1, _A1,
                        _A2, _A3, _A2, _A3, _A1, _A2, _A1, _A1, _A2, _A1, _A1, _A2)),
    "rts_backward": ("gyrostand.core.rts", "_rts_backward", f"UniTuple({_A1}, 2)", (
        _A2, _A3, _A2, _A3, _A3, _A1, _A1, _A1, _A2, _A1, _A2, _A2)),
    "score_run": ("gyrostand.core.ml.score", "_score_run", f"UniTuple({_A1}, 2)", (
        _A1, _A1, _A1, "f8", _A1, _A1, _A2, _A2, _A2, _A1, _A2,
        _A1, _A2, _A2, _A3, _A1, _A2, _A1, _A2, _A1, _A1, _A1, _A2, _A3, _A1)),
    "lkf_pass": ("gyrostand.core.lkf.kernel", "lkf_pass", "Tuple((f8, f8, i8))", (
        _A1, _A2, _A2, _A1, _A1, "f8", "f8", "f8", "f8", "f8", _A1, _A1, "b1",
        _A1, _A2, _A1, "i8", "i8", _A1, _A1)),
    "gm_profile": ("gyrostand.core.lkf.kernel", "gm_profile", "Tuple((f8, f8, i8))", (
        _A1, "f8", "f8", "f8", "f8")),
    "kf_step": ("gyrostand.core.kalman", "kf_step", "UniTuple(f8, 2)", (
        _A1, _A2, _A2, _A1, _A1, "f8", "f8")),
}


def signature(name: str) -> str:
    """Kernel ``name``'s numba signature, ``ret(arg, ...)``."""
    _, _, ret, args = SPECS[name]
    return f"{ret}({', '.join(args)})"


#: the source files of the kernels and of the helpers they inline
SOURCES = ("kalman.py", "rts.py", "ml/score.py", "lkf/kernel.py")


def source_key() -> int:
    """A 62-bit hash of the kernels' source files (:data:`SOURCES`) and :data:`SPECS`:
    the extension is used only where it equals the one it was built with."""
    h = hashlib.sha256(repr(sorted(SPECS.items())).encode())
    for name in SOURCES:
        h.update((_HERE / name).read_bytes())
    return int.from_bytes(h.digest()[:8], "little") >> 2


_state: dict[str, Any] = {}


def built() -> Any:
    """The extension module when it is there, matches this source and is not turned off
    (``GYROSTAND_KERNELS=jit``); else None. Looked up once a process."""
    if "module" not in _state:
        asked = os.environ.get("GYROSTAND_KERNELS", "").lower()
        _state["check_all"] = asked == "checked"
        mod = None
        if asked != "jit":
            try:
                found = importlib.import_module(MODULE)
                if int(found.source_key()) == source_key():
                    mod = found
                else:
                    logging.getLogger(__name__).info(
                        "the kernels compiled at install (%s) are older than their source: "
                        "numba compiles them instead (pip install -e . builds them again)",
                        found.__file__)
            except (ImportError, AttributeError, OSError):
                mod = None
        _state["module"] = mod
    return _state["module"]


#: kernel name -> calls whose arguments were not of the extension's types (then numba's
#: dispatcher ran them): a caller passing another type than :data:`SPECS` says
FALLBACKS: dict[str, int] = {}


def kernel(name: str, dispatcher: Callable[..., Any], *, made_here: bool = False
           ) -> Callable[..., Any]:
    """The function to call for kernel ``name`` (:data:`SPECS`): the extension's, else
    numba's ``dispatcher``.

    The extension's wrapper trusts its arguments' types: an array of another layout or
    type is read as if it were of its own (wrong memory, a crash). So each array argument
    is checked first (``carray``: a C-contiguous, aligned, writable float64 array of the
    rank of :data:`SPECS`), and a call that fails the check goes to the dispatcher and is
    counted in :data:`FALLBACKS`.

    ``made_here``: the caller made every array argument itself, of these types by
    construction (:func:`~.rts.writable` and the kernel's ``*_work`` allocator in the lines
    above the call; the LKF's arrays, allocated by its own object), and the call is too
    short for the check (the LKF's pass is called once a bin: 10 µs, of which the check
    of its 12 arrays would be 1.7): the extension's function as it is.
    ``GYROSTAND_KERNELS=checked`` checks these calls too (the tests' way of holding the
    callers to that claim)."""
    mod = built()
    if mod is None:
        return dispatcher
    if made_here and not _state.get("check_all"):
        return getattr(mod, name)  # type: ignore[no-any-return]
    call = _wrapped.get(name)
    if call is None:
        call = _wrapped[name] = _checked(name, getattr(mod, name), dispatcher)
    return call


_wrapped: dict[str, Callable[..., Any]] = {}


def _checked(name: str, fast: Callable[..., Any], dispatcher: Callable[..., Any]
             ) -> Callable[..., Any]:
    """``fast`` behind one generated test of every array argument (unrolled, as numba's
    dispatcher types its arguments in C: ~0.14 µs an array, 2.5 µs for ``kf_run``'s 18
    against a loop's 7.6), else ``dispatcher``."""
    import numpy as np

    types = SPECS[name][3]
    names = [f"a{i}" for i in range(len(types))]
    tests = [f"type({a}) is nd and {a}.ndim == {_RANK[t]} and ({a}.dtype is f8 or "
             f"{a}.dtype == f8) and {a}.flags.carray"
             for a, t in zip(names, types, strict=True) if _RANK[t]]
    arglist = ", ".join(names)
    src = (f"def call({arglist}):\n"
           f"    if {' and '.join(tests) or 'True'}:\n"
           f"        return fast({arglist})\n"
           f"    fell(name)\n"
           f"    return dispatcher({arglist})\n")
    ns: dict[str, Any] = {"nd": np.ndarray, "f8": np.dtype(np.float64), "fast": fast,
                          "dispatcher": dispatcher, "name": name, "fell": _fell}
    exec(src, ns)  # noqa: S102 - generated from SPECS alone
    return ns["call"]  # type: ignore[no-any-return]


def _fell(name: str) -> None:
    FALLBACKS[name] = FALLBACKS.get(name, 0) + 1


def build(out_dir: Path | str) -> Path:
    """Compile :data:`SPECS` into the extension module in ``out_dir`` (the package's
    ``gyrostand/core`` folder of a build or an in-place install); returns its path. Needs
    numba and a C compiler (it links with the platform's)."""
    import warnings

    from numba.core.compiler import Flags

    from .jit import dispatchers

    with warnings.catch_warnings():  # pycc's pending deprecation: it still builds
        warnings.simplefilter("ignore")
        from numba.pycc import CC, compiler

    class _ReleaseGil(Flags):  # type: ignore[misc]
        """pycc's wrappers hold the GIL by default; the dispatchers are ``nogil``."""

        def __init__(self, *args: Any, **kwargs: Any) -> None:
            super().__init__(*args, **kwargs)
            self.release_gil = True  # type: ignore[assignment]

    cc = CC(MODULE.rsplit(".", 1)[1], __name__)
    cc.output_dir = str(out_dir)
    cc.verbose = False
    for modname, _, _, _ in SPECS.values():
        importlib.import_module(modname)
    dispatchers()  # numba types each kernel's calls of the others through their globals
    for name, (modname, attr, _, _) in SPECS.items():
        cc.export(name, signature(name))(getattr(importlib.import_module(modname),
                                                  attr).py_func)
    ns: dict[str, Any] = {}
    exec(f"def source_key():\n    return {source_key()}\n", ns)  # a constant, compiled
    cc.export("source_key", "i8()")(ns["source_key"])
    plain = compiler.Flags
    compiler.Flags = _ReleaseGil  # type: ignore[misc]
    try:
        cc.compile()
    finally:
        compiler.Flags = plain  # type: ignore[misc]
    return Path(out_dir) / cc.output_file
