"""A bias jump (issue 23: an effect outside the vocabulary that the workbench certified with
a wrong term): the level shift judged against the saturated reference
(:mod:`gyrostand.core.diagnose.shift`) finds its instant and size in a run built from
frames, the verdict names it and ``term new`` writes it as a step that makes the model
adequate; a shape it is not — a step in T, glitches, a clean run — is not reported."""

from __future__ import annotations

import numpy as np
import pytest

from gyrostand.cli import main
from gyrostand.core.data import Samples
from gyrostand.core.diagnose import shift as sh
from gyrostand.core.diagnose.joint import joint_diagnose
from gyrostand.core.diagnose.reference import reference_fit
from gyrostand.core.diagnose.shapes import mean_tangents
from gyrostand.core.diagnose.verdict import diagnose
from gyrostand.core.ml.fit import ml
from gyrostand.core.model import Model, context
from gyrostand.core.validate import prepare

from .framelike import frame_run
from .plugin_run import fit_and_diagnose

BASE_MODEL = "markov,temp,bias"
#: the jump: deg/h at s from the start (the 4-h cycle's cold soak)
JUMP, AT = 0.15, 9000.0


def jump_run(tmp_path, seed, amp=JUMP, at=AT, **kw):
    return frame_run(tmp_path / f"jump{seed}.csv", seed=seed, drop=0.01,
                     event=lambda t: amp * (t > at), **kw)


def shift_of(path, model=BASE_MODEL):
    s = Samples.read_csv(path)
    m = Model.parse(model)
    fit = ml(s, m)
    return s, m, fit, reference_fit(s, m, fit)


@pytest.mark.parametrize("seed", [21, 22])
def test_a_jump_is_found_at_its_instant_with_its_size(tmp_path, seed):
    s, m, fit, ref = shift_of(jump_run(tmp_path, seed))
    r = sh.level_shift(s, ref)
    assert r is not None and r.significant, r
    # the binned run's clock starts inside the first bin: its bins sit at whole seconds
    # of the log, the jump inside one of them (its bin holds part of the step)
    assert abs(r.t - AT) <= 2.0, r
    assert abs(r.step - JUMP) < 3 * r.std and r.std < 0.03, r
    rep = diagnose(s, m, base=fit)
    assert not rep.adequate and rep.jump and rep.outside
    assert rep.reasons[0].startswith("a level shift of the drift at t = ")
    assert "outside the vocabulary" in rep.reasons[0]
    assert rep.to_dict()["level_shift"]["significant"] is True


def test_the_statistic_is_the_step_s_own_score_given_its_nuisance(tmp_path):
    # the group's Gram algebra (a step from its first t0 less impulses) against the step
    # from t0 filtered on its own and projected out of the reference's tangents, the
    # impulses after it and the steps in T, one least-squares problem: the same Z²
    s, _, _, ref = shift_of(jump_run(tmp_path, 23))
    r = sh.level_shift(s, ref)
    used = prepare(s, "level shift")
    model, vals = ref.model, dict(ref.fit.values)
    names, Tx = mean_tangents(model, vals, context(used, model))
    n_lin = len(model.names_of_kind("linear"))
    E, f = model.filter_columns(vals, used, Tx)
    e = E[:, 0] - E[:, 1:1 + n_lin] @ np.array([vals[n] for n in names[:n_lin]])
    ok = np.isfinite(e) & (f > 0)
    w = 1 / np.sqrt(f[ok])
    k0 = int(np.searchsorted(used.t - used.t[0], r.t))
    temp = np.nan_to_num(used.temp, nan=-np.inf)
    best = 0.0
    for t0 in range(k0 - 2, k0 + 1):  # the statistic's break leaves t0..t0+3 free
        first = max(t0 - sh.BEFORE, 0)
        near = temp[first - 1:t0 + sh.AFTER + sh.WINDOW + 1]
        levels = np.unique(near)[1:]
        Y = np.zeros((used.t.size, 2 + sh.WINDOW + len(levels)))
        Y[t0:, 1] = 1.0
        for j in range(sh.WINDOW):
            Y[t0 + j, 2 + j] = 1.0
        for j, v in enumerate(levels):
            Y[:, 2 + sh.WINDOW + j] = temp >= v
        C = model.filter_matrix(vals, used, Y)[0][ok, 1:] * w[:, None]
        N = np.column_stack([E[ok, 1:] * w[:, None], C[:, 1:]])
        x = C[:, 0] - N @ np.linalg.lstsq(N, C[:, 0], rcond=1e-10)[0]
        eps = e[ok] * w
        best = max(best, float(x @ eps) ** 2 / float(x @ x))
    # the levels of the group around the largest innovation differ by at most a sample's
    # reading at the edge: the same statistic to 2 %
    assert best == pytest.approx(r.stat, rel=0.02), (best, r.stat)


def test_a_step_in_t_glitches_and_clean_runs_are_not_a_jump(tmp_path):
    # a step of 0.4 deg/h above 40 °C jumps at every crossing: a shape in T (it scored
    # 202-285 before the steps in T were projected out)
    s, _, _, ref = shift_of(frame_run(tmp_path / "tstep.csv", seed=31, drop=0.01,
                                      response=lambda T: 0.4 * (T > 40.0)))
    r = sh.level_shift(s, ref)
    assert r is not None and not r.significant, r
    # glitches: single frames 40 σ off (each moves its bin by 4 σ of the white noise)
    path = frame_run(tmp_path / "emi.csv", seed=32, drop=0.01)
    rows = path.read_text().splitlines()
    rng = np.random.default_rng(7)
    for i in rng.choice(np.arange(100, len(rows) - 100), 6, replace=False):
        f = rows[i].split(",")
        f[1] = repr(float(f[1]) + 0.08 * float(rng.choice([-1.0, 1.0])))
        rows[i] = ",".join(f)
    path.write_text("\n".join(rows) + "\n")
    for p in (path, frame_run(tmp_path / "c33.csv", seed=33, drop=0.01),
              frame_run(tmp_path / "c34.csv", seed=34, drop=0.01, hours=2.0)):
        s, _, _, ref = shift_of(p)
        r = sh.level_shift(s, ref)
        assert r is not None and not r.significant, (p.name, r)


def test_term_new_writes_the_step_and_the_model_with_it_is_adequate(tmp_path, capsys):
    csv = jump_run(tmp_path, 24)
    assert main(["term", "new", "--from", str(csv), "--name", "jump_a"]) == 0
    out = capsys.readouterr().out
    assert "missing shape: a level shift of the drift at t = " in out, out
    pkg = tmp_path / "gyrostand-jump-a"
    src = (pkg / "gyrostand_jump_a.py").read_text()
    assert "A bias jump: an event of that run" in src
    step, d = fit_and_diagnose(pkg, csv, "jump_a", cwd=tmp_path)
    a = step["parameters"]["jump_a.a"]
    assert step["added"] == ["jump_a"] and step["p_value"] < 1e-6
    assert abs(a["value"] - JUMP) < 3 * a["std"], a
    assert "jump_a" in d["model"]
    assert d["level_shift"]["significant"] is False, d["level_shift"]
    assert d["adequate"] is True, d["reasons"]


def test_a_jump_in_one_of_two_runs_is_that_run_s_in_a_joint_diagnosis(tmp_path):
    # the joint fit absorbs an event of one run; each run is judged against its own
    # reference (Bonferroni over the runs), and a clean second run shows nothing
    jump = Samples.read_csv(jump_run(tmp_path, 25))
    clean = Samples.read_csv(frame_run(tmp_path / "c26.csv", seed=26, drop=0.01))
    rep = joint_diagnose([jump, clean], Model.parse(BASE_MODEL))
    assert not rep.adequate
    named = [r for r in rep.reasons if "a level shift of the drift" in r]
    assert len(named) == 1 and named[0].startswith("run 1 "), rep.reasons
    runs = rep.to_dict()["runs"]
    assert runs[0]["level_shift"]["significant"] is True
    assert abs(runs[0]["level_shift"]["t"] - AT) <= 2.0
    assert runs[1]["level_shift"]["significant"] is False
    assert runs[1]["periodic"]["significant"] is False
