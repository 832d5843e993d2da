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


def test_a_first_run_compiles_the_filters_block_product_once(tmp_path):
    """kf_run's wide Gram product is one kernel of one signature: its row count was an
    argument, and numba compiled it a second time for the literal 0 it met while typing
    (0.18 s of an empty-cache diagnose's 2.7 s for kf_run). A fresh process, an empty
    cache, a narrow and a wide pass (the last block partial): one signature."""
    import os
    import subprocess

    code = (
        "import numpy as np\n"
        "from gyrostand.core import kalman\n"
        "rng = np.random.default_rng(0)\n"
        "phi, q, p0 = np.array([0.99, 1.0]), np.array([0.1, 0.01]), np.ones(2)\n"
        "for m in (3, kalman.WIDE + 2):\n"
        "    kalman.kf_run(phi, q, p0, 0.5, kalman.NO_WEIGHTS, rng.normal(size=(1000, m)),"
        " False)\n"
        "print(len(kalman._gram_block.signatures), len(kalman._kf_run.signatures))\n")
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "empty"))
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                         text=True, check=True).stdout.split()
    assert out == ["1", "1"]
