"""numba's kernel cache and compile events (issue 25 item 3): where a fresh install caches
its kernels, and that a compilation is heard, named, once per signature."""

from __future__ import annotations

import sys

from gyrostand.core import jit


def test_an_unwritable_package_caches_in_the_user_cache_dir(tmp_path, monkeypatch):
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    monkeypatch.delitem(sys.modules, "numba")  # as before numba's first import
    monkeypatch.setattr(jit, "KERNEL_DIRS", (tmp_path / "site-packages-read-only",))
    jit.choose_cache_dir()
    assert jit.cache_dir() == tmp_path / "xdg" / "gyrostand" / "numba"


def test_a_writable_package_or_a_users_choice_is_kept(tmp_path, monkeypatch):
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    monkeypatch.delitem(sys.modules, "numba")
    monkeypatch.setattr(jit, "KERNEL_DIRS", (tmp_path,))
    jit.choose_cache_dir()
    assert jit.cache_dir() == tmp_path / "__pycache__"
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "mine"))
    monkeypatch.setattr(jit, "KERNEL_DIRS", (tmp_path / "missing",))
    jit.choose_cache_dir()
    assert jit.cache_dir() == tmp_path / "mine"


def test_a_compilation_is_heard_once_per_signature():
    from numba import njit

    heard: list[tuple[str, bool]] = []
    jit.listen()
    stop = jit.watch(lambda kernel, started: heard.append((kernel, started)))

    @njit
    def _fresh_kernel(x):
        return x + 1.0

    try:
        assert _fresh_kernel(1.0) == 2.0 and _fresh_kernel(2.0) == 3.0
        assert _fresh_kernel(1) == 2  # an int: a second signature, a second compilation
    finally:
        stop()
    assert heard == [("fresh_kernel", True), ("fresh_kernel", False)] * 2
    _fresh_kernel(3.0j)  # after stop(): not heard
    assert len(heard) == 4
