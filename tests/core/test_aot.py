"""The kernels compiled at install (issue 25 item 3, gyrostand.core.aot): the install built
them; each gives numba's numbers to the bit; a kernel whose source changed, a call with
arrays of another type, or GYROSTAND_KERNELS=jit goes to numba; they release the GIL; the
types they were built for are the ones the callers pass; a diagnosis and the LKF use them
without one fallback."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from gyrostand.core import aot, kalman, rts
from gyrostand.core.ml import score

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def ext():
    mod = aot.built()
    assert mod is not None, (
        "the kernels were not compiled at install (pip install -e . prints why): "
        "gyrostand.core._kernels is missing or was built from another source")
    return mod


@pytest.fixture
def numba_only(monkeypatch):
    """This process as if the extension were not there (numba's dispatchers)."""
    monkeypatch.setitem(aot._state, "module", None)


def _filter_args(rng, N=3000, m=4, n=2, weighted=True, gaps=True):
    Y = rng.normal(size=(N, m))
    if gaps:
        Y[rng.choice(N, N // 20, replace=False), 0] = np.nan  # dropped bins
        Y[100:160, 0] = np.nan  # an outage
    rw = rng.uniform(0.8, 1.3, N) if weighted else kalman.NO_WEIGHTS
    phi = np.array([0.995, 1.0][:n])
    q = np.array([0.01, 1e-5][:n])
    return phi, q, np.array([2.0, 0.5][:n]), 0.3, rw, Y


@pytest.mark.parametrize("m", [1, 4, kalman.WIDE + 3])
@pytest.mark.parametrize("store", [False, True])
@pytest.mark.parametrize("weighted", [False, True])
def test_the_filter_gives_numbas_numbers_to_the_bit(ext, m, store, weighted):
    phi, q, p0, r, rw, Y = _filter_args(np.random.default_rng(m), m=m, weighted=weighted)
    out = []
    for run in (ext.kf_run, kalman._kf_run):
        out.append(run(phi, q, p0, r, rw, Y, store, *kalman.kf_work(2, *Y.shape, store)))
    (E1, f1, G1, s1, n1), (E2, f2, G2, s2, n2) = out
    assert np.array_equal(E1, E2, equal_nan=True) and np.array_equal(f1, f2, equal_nan=True)
    assert np.array_equal(G1, G2) and s1 == s2 and n1 == n2
    assert n1 == np.isfinite(Y[:, 0]).sum() and np.isfinite(s1)


def test_the_smoother_score_and_response_give_numbas_numbers_to_the_bit(ext):
    rng = np.random.default_rng(7)
    phi, q, p0, r, rw, Y = _filter_args(rng, N=2000, m=1)
    y = np.ascontiguousarray(Y[:, 0])
    f1 = ext.rts_forward(phi, q, p0, r, rw, y, *rts.forward_work(2, y.size))
    f2 = rts.rts_forward(phi, q, p0, r, rw, y, *rts.forward_work(2, y.size))
    for a, b in zip(f1, f2, strict=True):
        assert np.array_equal(a, b)
    alone = [run(phi, q, p0, r, rw, y, *rts.forward_work(2, y.size, covariances=False))
             for run in (ext.rts_forward, rts.rts_forward)]  # the states alone, held P
    assert np.array_equal(alone[0][2], alone[1][2]) and np.array_equal(alone[0][2], f1[2])
    xp, Pp, xf, Pf = f1
    J = np.empty_like(Pf)
    J[:-1] = (Pf[:-1] * phi[np.newaxis, np.newaxis, :]) @ np.linalg.pinv(Pp[1:])
    b1 = ext.rts_backward(xp, Pp, xf, Pf, J, *rts.backward_work(2, y.size))
    b2 = rts._rts_backward(xp, Pp, xf, Pf, J, *rts.backward_work(2, y.size))
    assert np.array_equal(b1[0], b2[0]) and np.array_equal(b1[1], b2[1])
    d = 3
    deriv = [rng.normal(size=(d, 2)) * 0.01 for _ in range(3)]
    dr, du = rng.normal(size=d) * 0.01, rng.normal(size=(d, y.size))
    du[:, np.isnan(y)] = np.nan
    g = [run(phi, q, p0, r, rw, y, *deriv, dr, du, *score.score_work(2, d))
         for run in (ext.score_run, score._score_run)]
    assert np.array_equal(g[0][0], g[1][0]) and np.array_equal(g[0][1], g[1][1])
    assert np.isfinite(g[0][0]).all()
    u = rng.normal(size=500)
    x1 = ext.first_order_response(u, 0.97, 0.2, 0.3, 1.5, np.empty(500))
    assert np.array_equal(x1, kalman._first_order_response(u, 0.97, 0.2, 0.3, 1.5,
                                                           np.empty(500)))


def test_the_online_step_gives_numbas_numbers_to_the_bit(ext):
    rng = np.random.default_rng(3)
    n = 4
    L = rng.normal(size=(n, n))
    start = (rng.normal(size=n), L @ L.T + np.eye(n))
    A, Qd = np.eye(n) + 0.01 * rng.normal(size=(n, n)), np.full(n, 1e-3)
    states = []
    for step in (ext.kf_step, kalman.kf_step):
        x, P = start[0].copy(), start[1].copy()
        ef = [step(x, P, A if k % 3 else np.zeros((0, 0)), Qd, rng_h, 0.2, z)
              for k, (rng_h, z) in enumerate(zip(np.random.default_rng(1).normal(size=(50, n)),
                                                 [np.nan if k % 11 == 5 else 0.1 * k
                                                  for k in range(50)], strict=True))]
        states.append((ef, x, P))
    assert states[0][0] == states[1][0] or np.array_equal(
        np.array(states[0][0]), np.array(states[1][0]), equal_nan=True)
    assert np.array_equal(states[0][1], states[1][1]) and np.array_equal(states[0][2],
                                                                         states[1][2])


def test_every_kernel_called_from_python_is_compiled_at_install():
    """A kernel added later and left out of SPECS would compile on every first run again:
    each numba dispatcher of the kernel modules is in SPECS, inlined into them, or a
    callee of one (compiled into it)."""
    from numba.core.registry import CPUDispatcher

    from gyrostand.core import jit
    from gyrostand.core.lkf import kernel as lkf_kernel

    jit.dispatchers()  # the lazy kernels replaced by numba's dispatchers
    callees = {"_gram_block"}  # kf_run's block product
    exported = {attr for _, attr, _, _ in aot.SPECS.values()}
    for mod in (kalman, rts, score, lkf_kernel):
        for name, obj in vars(mod).items():
            if not isinstance(obj, CPUDispatcher) or obj.py_func.__module__ != mod.__name__:
                continue
            inlined = obj.targetoptions.get("inline") == "always"
            assert inlined or name in exported or name in callees, (mod.__name__, name)


def test_an_edited_kernel_or_a_request_goes_to_numba(monkeypatch, ext):
    key = aot.source_key()
    monkeypatch.setattr(aot, "_state", {})
    monkeypatch.setattr(aot, "source_key", lambda: key + 1)  # the source moved on
    assert aot.built() is None
    assert aot.kernel("kf_run", kalman._kf_run) is kalman._kf_run
    monkeypatch.setattr(aot, "_state", {})
    monkeypatch.setattr(aot, "source_key", lambda: key)
    monkeypatch.setenv("GYROSTAND_KERNELS", "jit")
    assert aot.built() is None
    monkeypatch.setattr(aot, "_state", {})
    monkeypatch.delenv("GYROSTAND_KERNELS")
    assert aot.built() is ext


def test_arrays_of_another_type_go_to_numba_not_to_the_extension(ext, monkeypatch):
    """The extension reads its arguments as the types it was built for: a strided, a
    float32 or a read-only array would be read wrongly (a crash), so they go to numba."""
    monkeypatch.setattr(aot, "FALLBACKS", {})
    step = aot.kernel("kf_step", kalman.kf_step)
    H = np.ones(3)
    P_t = np.asfortranarray(np.eye(3) + 0.1)
    frozen = np.zeros(3)
    frozen.flags.writeable = False
    for x, P, h in ((np.zeros(3), P_t, H), (np.zeros(6)[::2], np.eye(3), H),
                    (np.zeros(3), np.eye(3), H.astype(np.float32)),
                    (frozen.copy(), np.eye(3), np.ones(3))):
        e, f = step(x, P, np.zeros((0, 0)), np.zeros(3), h, 0.5, 1.0)
        assert e == 1.0 and f > 0.5
    assert aot.FALLBACKS == {"kf_step": 3}
    e, f = step(np.zeros(3), np.eye(3), np.zeros((0, 0)), np.zeros(3), frozen, 0.5, 1.0)
    assert aot.FALLBACKS == {"kf_step": 4} and e == 1.0 and f == 0.5


def test_the_kernels_release_the_gil(ext):
    """Two candidates' refits run on two threads: while one thread is in the filter, the
    other runs Python."""
    phi, q, p0, r, rw, Y = _filter_args(np.random.default_rng(0), N=400_000, m=8)
    work = kalman.kf_work(2, *Y.shape, False)
    started, done = threading.Event(), threading.Event()

    def filter_once():
        started.set()
        ext.kf_run(phi, q, p0, r, rw, Y, False, *work)
        done.set()

    t = threading.Thread(target=filter_once)
    t.start()
    started.wait()
    spins = 0
    while not done.is_set():
        spins += 1
    t.join()
    assert spins > 10_000  # held, the GIL would let this loop turn only at switches


def test_the_extension_was_built_for_the_types_the_callers_pass(ext, numba_only):
    """numba types the callers' arguments on a first call: its signature of each kernel
    is the one the extension was built for (through the public functions, as they call)."""
    from numba.core import sigutils

    from gyrostand.core.lkf.kernel import gm_profile, lkf_pass

    phi, q, p0, r, rw, Y = _filter_args(np.random.default_rng(0), N=300)
    kalman.kf_run(phi, q, p0, r, rw, Y, False)
    kalman.first_order_response(np.ones(5), 0.9, 0.1, 0.1, 0.0)
    score.warm()
    rts.warm()
    dispatchers = {"kf_run": kalman._kf_run, "first_order_response":
                   kalman._first_order_response, "rts_forward": rts.rts_forward,
                   "rts_backward": rts._rts_backward, "score_run": score._score_run,
                   "lkf_pass": lkf_pass, "gm_profile": gm_profile, "kf_step": kalman.kf_step}
    assert set(dispatchers) == set(aot.SPECS)
    for name in ("kf_run", "first_order_response", "rts_forward", "rts_backward",
                 "score_run"):
        args, _ = sigutils.normalize_signature(aot.signature(name))
        assert tuple(args) in dispatchers[name].signatures, name


def test_a_diagnosis_and_the_lkf_run_on_the_extension_without_a_fallback(ext, monkeypatch):
    """Every call checked (GYROSTAND_KERNELS=checked), those whose callers say they made
    their arrays themselves too: a diagnosis, the LKF over a record, the daemon's online
    LKF (its pass once a bin) and the one-bin filter pass every check."""
    from gyrostand.config import LkfConfig
    from gyrostand.core import identify
    from gyrostand.core.diagnose.verdict import diagnose
    from gyrostand.core.lkf.filter import OnlineLKF
    from gyrostand.core.model import Model
    from gyrostand.core.profiles import chamber_profile
    from gyrostand.core.simulation import simulate
    from gyrostand.session.online import LkfTrack

    monkeypatch.setattr(aot, "FALLBACKS", {})
    monkeypatch.setitem(aot._state, "check_all", True)
    monkeypatch.setattr(aot, "_wrapped", {})
    m = Model.parse("markov,temp,bias")
    s = simulate(Model.parse("markov,temp,bias,temp_rate"),
                 {"markov.beta": 0.01, "markov.sigma": 0.05, "temp.gamma": -0.0005,
                  "white.sigma": 0.02, "bias.b": 0.3, "temp_rate.k": 5.0},
                 chamber_profile(1.0), seed=2)
    rep = diagnose(s, m)
    assert rep.candidates and np.isfinite(rep.fit.loglik)
    r = identify(s, m, "lkf")
    assert np.isfinite(r.value("temp.gamma"))
    online = OnlineLKF(m, s.dt, held={"markov.sigma": 0.05, "white.sigma": 0.02})
    for y, T in zip(s.drift[:200], s.temp[:200], strict=True):
        online.update(float(y), float(T))
    tracker = LkfTrack(m, LkfConfig(), s.dt)
    for y, T in zip(s.drift[:1500].tolist(), s.temp[:1500].tolist(), strict=True):
        tracker.update(y, T)
    assert np.isfinite(tracker.estimate().values["temp.gamma"][0])
    assert aot.FALLBACKS == {}
    assert set(aot._wrapped) >= {"kf_run", "lkf_pass", "score_run", "rts_forward"}


def test_the_command_gives_the_same_output_on_the_extension_and_on_numba(tmp_path):
    """A whole diagnose, once on the extension and once on numba (an empty cache)."""
    from gyrostand.core.model import Model
    from gyrostand.core.profiles import chamber_profile
    from gyrostand.core.simulation import simulate

    s = simulate(Model.parse("markov,temp,bias,temp2"),
                 {"markov.beta": 0.01, "markov.sigma": 0.05, "temp.gamma": -0.0005,
                  "white.sigma": 0.02, "bias.b": 0.3, "temp2.gamma2": 2e-5},
                 chamber_profile(1.0), seed=4)
    csv = tmp_path / "run.csv"
    np.savetxt(csv, np.column_stack([s.t, s.drift, s.temp]), delimiter=",",
               header="t,drift,temp", comments="", fmt="%.9g")
    outs = []
    for kernels in ("", "jit"):
        env = dict(os.environ, GYROSTAND_KERNELS=kernels,
                   NUMBA_CACHE_DIR=str(tmp_path / f"numba-{kernels or 'aot'}"))
        p = subprocess.run([sys.executable, "-m", "gyrostand", "-q", "diagnose", str(csv),
                            "--format", "json"], env=env, capture_output=True, text=True,
                           cwd=ROOT, timeout=600)
        assert p.returncode in (0, 1), p.stderr
        outs.append(_timeless(json.loads(p.stdout)))
    assert outs[0] == outs[1] and outs[0]["candidates"]


def _timeless(doc):
    """A JSON document without its timings (``seconds``: the one thing that differs)."""
    if isinstance(doc, dict):
        return {k: _timeless(v) for k, v in doc.items() if k != "seconds"}
    if isinstance(doc, list):
        return [_timeless(v) for v in doc]
    return doc


@pytest.mark.parametrize("kernels", ["", "jit"])
def test_a_command_on_the_extension_imports_no_numba(tmp_path, kernels):
    """The kernels are numba's only on first need: on the extension a whole diagnose never
    imports numba (0.2-0.3 s of start-up); on numba's path it does, and compiles."""
    code = (
        "import sys\n"
        "import numpy as np\n"
        "from gyrostand.core.model import Model\n"
        "from gyrostand.core.profiles import chamber_profile\n"
        "from gyrostand.core.simulation import simulate\n"
        "from gyrostand.core.diagnose.verdict import diagnose\n"
        "m = Model.parse('markov,temp,bias')\n"
        "s = simulate(m, {'markov.beta': 0.01, 'markov.sigma': 0.05, 'temp.gamma': -5e-4,"
        " 'white.sigma': 0.02, 'bias.b': 0.3}, chamber_profile(1.0), seed=3)\n"
        "rep = diagnose(s, m)\n"
        "print('numba' in sys.modules, rep.fit.loglik)\n")
    env = dict(os.environ, GYROSTAND_KERNELS=kernels, NUMBA_CACHE_DIR=str(tmp_path))
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                         text=True, check=True, cwd=ROOT, timeout=600).stdout.split()
    assert out[0] == ("True" if kernels else "False")
    assert np.isfinite(float(out[1]))
