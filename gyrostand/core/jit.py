"""numba's compiled kernels: where they are cached, and who hears of a compilation.

Every kernel (:mod:`.kalman`, :mod:`.rts`, :mod:`.lkf.kernel`) is ``njit(cache=True)``
without a signature: numba compiles it on its first call, for the argument types of that
call, and writes the machine code to its cache, so a later process loads it (tens of ms)
instead of compiling it again (0.2-2 s each). A command compiles only the kernels it
calls. An install compiles them ahead of time (:mod:`.aot`): then nothing here compiles
unless a kernel's source changed since, or ``GYROSTAND_KERNELS=jit`` asks for numba.

The kernels are defined with this module's :func:`njit`: numba's dispatchers are made,
and numba imported, on first need (:func:`dispatchers`), so a command whose kernels all
come from the install's extension never imports numba.

Where the cache lives (issue 25): beside the package (``gyrostand/core/__pycache__``,
numba's default) when the package's folders are writable, else the user's cache folder
``$XDG_CACHE_HOME/gyrostand/numba`` (``~/.cache/gyrostand/numba``): :func:`choose_cache_dir`
sets ``NUMBA_CACHE_DIR`` to it before numba is imported (importing :mod:`gyrostand.core`
does). A ``NUMBA_CACHE_DIR`` the user set is kept.

Who hears of a compilation: :func:`watch` adds a callback told ``(kernel, True)`` when an
outermost compilation starts and ``(kernel, False)`` when it ends (the command line shows
it as progress); the kernels' modules call :func:`listen` when they load, which forwards
numba's ``numba:compile`` events to the callbacks. numba compiles one function at a time
(its compiler lock), so one depth counter serves every thread.
"""

from __future__ import annotations

import os
import sys
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

__all__ = ["LazyKernel", "cache_dir", "choose_cache_dir", "dispatchers", "expect", "expecting",
           "listen", "njit", "ready", "user_cache_dir", "watch"]

#: the folders whose kernels numba caches beside their source by default
KERNEL_DIRS = (Path(__file__).resolve().parent, Path(__file__).resolve().parent / "lkf")

Watcher = Callable[[str, bool], None]
_watchers: list[Watcher] = []
_state: dict[str, Any] = {"listening": False, "depth": 0}


def user_cache_dir() -> Path:
    """The user's cache folder for gyrostand's kernels (XDG: ``$XDG_CACHE_HOME`` else
    ``~/.cache``, then ``gyrostand/numba``)."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "gyrostand" / "numba"


def _writable(folder: Path) -> bool:
    cache = folder / "__pycache__"
    return os.access(cache if cache.is_dir() else folder, os.W_OK)


def choose_cache_dir() -> None:
    """Point numba at :func:`user_cache_dir` when a kernel folder of the package is not
    writable (a system-wide or read-only install), unless ``NUMBA_CACHE_DIR`` is set or
    numba is already imported (its configuration is read once, on import)."""
    if "NUMBA_CACHE_DIR" in os.environ or "numba" in sys.modules:
        return
    if not all(_writable(d) for d in KERNEL_DIRS):
        os.environ["NUMBA_CACHE_DIR"] = str(user_cache_dir())


def cache_dir() -> Path:
    """Where this process's compiled kernels are cached."""
    given = os.environ.get("NUMBA_CACHE_DIR")
    return Path(given) if given else KERNEL_DIRS[0] / "__pycache__"


def watch(callback: Watcher) -> Callable[[], None]:
    """Tell ``callback(kernel, started)`` of every outermost compilation from now on;
    returns the function that stops it."""
    _watchers.append(callback)

    def unwatch() -> None:
        if callback in _watchers:
            _watchers.remove(callback)

    return unwatch


def _kernel(ev: Any) -> str:
    fn = getattr((ev.data or {}).get("dispatcher"), "py_func", None)
    return str(getattr(fn, "__name__", "kernel")).lstrip("_")


def listen() -> None:
    """Forward numba's compile events to the watchers (once per process). Before numba is
    imported this only asks for it: :func:`dispatchers` listens when it imports numba
    (the kernels compiled at install need neither)."""
    if _state["listening"]:
        return
    if "numba" not in sys.modules:
        return  # dispatchers() listens when it imports numba
    from numba.core import event

    class _Forward(event.Listener):  # type: ignore[misc]
        def on_start(self, ev: Any) -> None:
            _state["depth"] += 1
            if _state["depth"] == 1:
                for w in list(_watchers):
                    w(_kernel(ev), True)

        def on_end(self, ev: Any) -> None:
            _state["depth"] -= 1
            if _state["depth"] == 0:
                for w in list(_watchers):
                    w(_kernel(ev), False)

    event.register("numba:compile", _Forward())
    _state["listening"] = True


#: kernels another process compiles for this one (:mod:`.prewarm`), each with the event
#: set when it is in the cache (or the other process is gone)
_expected: dict[str, threading.Event] = {}
#: the longest a first call waits for the other process's kernel (s), then compiles it
EXPECT_WAIT_S = 120.0


def expect(names: list[str]) -> dict[str, threading.Event]:
    """Note that another process is compiling the kernels ``names`` into the cache; set
    each returned event when it is there (or will not be)."""
    for n in names:
        _expected.setdefault(n, threading.Event())
    return {n: _expected[n] for n in names}


def expecting(name: str) -> bool:
    """Whether another process was asked to compile kernel ``name`` (:func:`expect`)."""
    return name in _expected


def ready(name: str) -> None:
    """Before a first call of kernel ``name``: wait while another process still compiles
    it (:mod:`.prewarm`), so this one loads it from the cache instead of compiling it."""
    ev = _expected.get(name)
    if ev is not None and not ev.is_set():
        ev.wait(EXPECT_WAIT_S)


# ---- kernels whose numba dispatchers are made on first need -------------------------------

#: every kernel defined with :func:`njit`, in definition order
_lazy: list[LazyKernel] = []
_made = threading.Lock()


class LazyKernel:
    """A kernel defined with :func:`njit`: its Python function (``py_func``) until numba is
    needed, then numba's dispatcher, to which calls and attributes (``signatures``,
    ``targetoptions`` ...) go. A process whose kernels all come from the extension built
    at install (:mod:`.aot`) never imports numba (0.2-0.3 s of every command's start-up:
    numba, and the scipy.linalg its BLAS check imports)."""

    def __init__(self, func: Callable[..., Any], options: dict[str, Any]) -> None:
        self.py_func = func
        self.options = options
        self.dispatcher: Any = None
        self.__name__ = func.__name__
        self.__qualname__ = func.__qualname__
        self.__module__ = func.__module__
        self.__doc__ = func.__doc__

    def __call__(self, *args: Any) -> Any:
        if self.dispatcher is None:
            dispatchers()
        return self.dispatcher(*args)

    def __getattr__(self, name: str) -> Any:
        if name == "dispatcher":  # (before __init__ set it: a copy being made)
            raise AttributeError(name)
        if self.dispatcher is None:
            dispatchers()
        return getattr(self.dispatcher, name)

    def __repr__(self) -> str:
        return f"<kernel {self.__module__}.{self.__qualname__} (numba on first need)>"


def njit(**options: Any) -> Callable[[Callable[..., Any]], Any]:
    """numba's ``njit(**options)``, made on first need (:class:`LazyKernel`): the kernel
    modules' decorator, so that importing them imports no numba."""

    def define(func: Callable[..., Any]) -> Any:
        kernel = LazyKernel(func, options)
        with _made:
            _lazy.append(kernel)
            if not _state.get("made"):
                return kernel
        from numba import njit as numba_njit  # numba in use already: its dispatcher now

        kernel.dispatcher = numba_njit(**options)(func)
        return kernel.dispatcher

    return define


def dispatchers() -> None:
    """Import numba and make every kernel's dispatcher (once a process). The lazy kernels
    in gyrostand's modules are replaced by their dispatchers, since numba types a kernel's
    calls of others through its module's globals."""
    with _made:
        if _state.get("made"):
            return
        from numba import njit as numba_njit

        for kernel in _lazy:
            if kernel.dispatcher is None:
                kernel.dispatcher = numba_njit(**kernel.options)(kernel.py_func)
        for name, mod in list(sys.modules.items()):
            if mod is None or not name.startswith("gyrostand."):
                continue
            for attr, value in list(vars(mod).items()):
                if isinstance(value, LazyKernel):
                    setattr(mod, attr, value.dispatcher)
        _state["made"] = True
    listen()
