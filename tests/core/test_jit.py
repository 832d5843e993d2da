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


def test_a_first_run_compiles_each_kernel_once_and_no_allocation_in_them(tmp_path):
    """What a fresh install compiles (#25 item 3). kf_run's wide Gram product is one
    kernel of one signature: its row count was an argument, and numba compiled it a
    second time for the literal 0 it met while typing (0.18 s). And no kernel allocates:
    numba compiled each ``np.zeros``/``np.empty``/``np.ones`` of a kernel for its own rank
    (score_run's 13 arrays were 0.6 s of its 2.1 s), so the callers pass every output and
    work array. A fresh process, an empty cache: the filter narrow and wide (the last
    block partial), ML's score, the smoother, a first-order response."""
    import os
    import subprocess

    code = (
        "import numpy as np\n"
        "from numba.core import event\n"
        "heard = []\n"
        "class L(event.Listener):\n"
        "    def on_start(self, ev): heard.append(ev.data['dispatcher'].py_func.__qualname__)\n"
        "    def on_end(self, ev): pass\n"
        "event.register('numba:compile', L())\n"
        "from gyrostand.core import kalman, rts\n"
        "from gyrostand.core.ml import score\n"
        "rng = np.random.default_rng(0)\n"
        "phi, q, p0 = np.array([0.99, 1.0]), np.array([0.1, 0.01]), np.ones(2)\n"
        "for m in (3, kalman.WIDE + 2):\n"
        "    kalman.kf_run(phi, q, p0, 0.5, kalman.NO_WEIGHTS, rng.normal(size=(1000, m)),"
        " False)\n"
        "score.warm(); rts.warm()\n"
        "kalman.first_order_response(np.ones(5), 0.9, 0.1, 0.1, 0.0)\n"
        "print(len(kalman._gram_block.signatures), len(kalman._kf_run.signatures))\n"
        "print(' '.join(heard))\n")
    # numba's path, not the kernels compiled at install (gyrostand.core.aot)
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "empty"), GYROSTAND_KERNELS="jit")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                         text=True, check=True).stdout.splitlines()
    assert out[0].split() == ["1", "1"]
    heard = out[1].split()
    for kernel in ("_kf_run", "_gram_block", "_score_run", "rts_forward", "_rts_backward",
                   "_first_order_response"):
        assert heard.count(kernel) == 1, (kernel, heard)
    allocations = [h for h in heard if h.startswith(("ol_np_zeros", "ol_np_empty",
                                                      "ol_np_ones"))]
    assert allocations == [], heard
