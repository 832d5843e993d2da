"""``gyrostand term new --from RUN`` (issue 23 item 3): an effect outside the vocabulary —
a cubic response to T — is shown by the reference, written as a plugin term by a sparse
formula, and that term, added with ``fit --add``, makes the model adequate."""

from __future__ import annotations

import numpy as np
import pytest

from gyrostand import exitcodes
from gyrostand.cli import main
from gyrostand.core.data import Samples
from gyrostand.core.diagnose.formula import sparse_formula
from gyrostand.core.diagnose.reference import Partial
from gyrostand.core.model import Model
from gyrostand.core.profiles import chamber_profile
from gyrostand.core.simulation import simulate

from .plugin_run import fit_and_diagnose

BASE = {"markov.beta": 0.01, "markov.sigma": 0.05, "temp.gamma": -0.0005,
        "white.sigma": 0.02, "bias.b": 0.3}


def test_the_sparse_formula_names_the_form_of_a_known_curve():
    x = np.linspace(20.0, 60.0, 41)
    cubic = 3e-5 * (x - 40.0) ** 3 + 0.01 * x
    q = Partial("temperature", "T", "degC", x, cubic, np.full_like(x, 0.01), 50.0, 5, 1e-8)
    f = sparse_formula(q)
    assert [n for n, _ in f.forms] == ["((T-40)/20)^3"] and f.r2 > 0.999
    # a = the change at the peak; g has peak 1 on the curve's range
    assert abs(f.amplitude) == pytest.approx(3e-5 * 20.0 ** 3, rel=1e-6)
    assert np.max(np.abs(f(x))) == pytest.approx(1.0)
    # a·g(x) is the curve beyond its constant and linear part
    rest = cubic - f.amplitude * f(x)
    assert np.ptp(rest - np.polyval(np.polyfit(x, rest, 1), x)) < 1e-9
    step = 0.2 * (x > 45.0)
    g = sparse_formula(Partial("temperature", "T", "degC", x, step, np.full_like(x, 0.01),
                               50.0, 5, 1e-8))
    assert g.forms[0][0].startswith("step at 4") and g.r2 > 0.9
    with pytest.raises(ValueError, match="rate terms"):
        sparse_formula(Partial("rate", "dT/dt", "degC/s", x, cubic, x, 1.0, 1, 0.5))


def test_term_new_writes_a_plugin_that_makes_the_model_adequate(tmp_path, capsys):
    s = simulate(Model.parse("markov,temp,bias"), BASE, chamber_profile(3.0), seed=11)
    rng = np.random.default_rng(3)
    drift = s.drift + 4e-5 * (s.temp - 35.0) ** 3
    temp = np.round((s.temp + 0.01 * rng.standard_normal(len(s))) / 0.05) * 0.05
    csv = tmp_path / "cubic.csv"
    Samples.from_arrays(s.t, drift, temp).to_csv(csv)

    assert main(["term", "new", "--from", str(csv), "--name", "cubic_t"]) == 0
    out = capsys.readouterr().out
    assert "partial effect of T" in out, out
    r2 = float(out.split("R² ")[1].split(" ")[0])
    assert "score LM" in out, out
    assert r2 > 0.9, out
    pkg = tmp_path / "gyrostand-cubic-t"
    assert (pkg / "gyrostand_cubic_t.py").is_file() and (pkg / "pyproject.toml").is_file()
    assert 'cubic_t = "gyrostand_cubic_t:CubicT"' in (pkg / "pyproject.toml").read_text()
    # it exists
    assert main(["term", "new", "--from", str(csv), "--name", "cubic_t"]) == exitcodes.CANTCREAT
    assert "exists" in capsys.readouterr().err

    # the generated module, registered as the session file's plugins: would, then the
    # real command line: fit --add the term, diagnose the bigger model
    step, d = fit_and_diagnose(pkg, csv, "cubic_t")
    assert step["added"] == ["cubic_t"] and step["p_value"] < 1e-6
    a = step["parameters"]["cubic_t.a"]
    assert abs(a["value"]) > 4 * a["std"]
    # the polynomial at the output: z³ (g, peak 1 at an end of the range) and its lower
    # powers, each its own coefficient; 4e-5·(T − 35)³ with z = (T − 27.5)/17.55 is
    # 0.2162 z³ − 0.2772 z² + 0.1185 z − 0.0169 (the constant is the bias's)
    b1, b2 = step["parameters"]["cubic_t.b1"], step["parameters"]["cubic_t.b2"]
    assert abs(a["value"]) == pytest.approx(0.2162, rel=0.1), a
    assert b2["value"] == pytest.approx(-0.2772, rel=0.1), b2
    assert abs(b1["value"] - 0.1185) < 3 * b1["std"], b1
    assert "cubic_t" in d["model"]
    assert d["reference"]["significant"] is False, d["reference"]["p_value"]
    assert d["adequate"] is True, d["reasons"]


def test_the_next_line_of_an_effect_outside_the_vocabulary_is_term_new():
    from gyrostand.report.text import term_new_command

    assert term_new_command("/v/bin/gyrostand fit '/runs/a b' --gyro az") == \
        "/v/bin/gyrostand term new --from '/runs/a b' --gyro az"


def test_after_temp2_the_formula_is_the_shape_beyond_it(tmp_path, capsys):
    # a cubic in T: the workbench adds temp2 (its quadratic part) first, then shows the
    # rest outside the vocabulary. The formula is chosen by the score of each library
    # form at the current fit (temp2 readjusting), so it is the cubic alone, and its
    # coefficient the cubic's leading one (invariant to the centre): a·S³. Fitted to the
    # reference's partial-effect curve instead it was two steps (the curve's band as wide
    # as the curve, its T basis nearly collinear with T²).
    s = simulate(Model.parse("markov,temp,bias"), BASE, chamber_profile(3.0), seed=11)
    rng = np.random.default_rng(3)
    a = 6e-5
    drift = s.drift + a * (s.temp - 32.0) ** 3
    temp = np.round((s.temp + 0.01 * rng.standard_normal(len(s))) / 0.05) * 0.05
    csv = tmp_path / "cubic.csv"
    Samples.from_arrays(s.t, drift, temp).to_csv(csv)
    assert main(["term", "new", "--from", str(csv), "--name", "cubic_u",
                 "--model", "markov,temp,bias,temp2"]) == 0
    line = [x for x in capsys.readouterr().out.splitlines() if x.startswith("formula:")][0]
    g = line.split("g = ")[1].split(" (normalised")[0]
    assert g.count("·") == 1 and g.endswith("^3"), line  # one form: the cubic
    coef = float(g.split("·")[0])
    half = float(g.split("/")[1].split(")")[0])
    assert abs(coef) == pytest.approx(a * half ** 3, rel=0.15), (line, a * half ** 3)


@pytest.mark.parametrize("seed", [3, 5])
def test_a_sharp_step_in_t_is_placed_and_sized_by_the_data(tmp_path, seed):
    # a step of 0.4 deg/h where the chamber passes 40 °C, in a 4-h run built from frames:
    # the library's grid steps sit 0.7 °C apart and 0.7 °C wide; the chosen one's centre
    # and width are refined by the score statistic (a grid step left LM ~160 where the
    # refined one has ~1500, and the plugin left the lack of fit to temp_rate), in two
    # passes: one pass's 0.035-°C centres and 0.021-°C width left seed 5 a second step at
    # 40.11 °C beside the first; two put one step within 0.003 °C of 40 °C
    from gyrostand.core.diagnose.formula import score_formula
    from gyrostand.core.diagnose.reference import reference_fit
    from gyrostand.core.ml.fit import ml

    from .framelike import frame_run

    run = frame_run(tmp_path / "step.csv", seed=seed, response=lambda T: 0.4 * (T > 40.0))
    s = Samples.read_csv(run)
    model = Model.parse("markov,temp,bias")
    fit = ml(s, model)
    ref = reference_fit(s, model, fit)
    assert ref.significant
    q = [q for q in ref.missing() if q.variable == "T"][0]
    f = score_formula(q, s, model, fit)
    steps = [e for n, e in f.forms if n.startswith("step at")]
    assert steps, f.forms
    import re
    tc, w = map(float, re.search(r"x - ([-0-9.e]+)\) / ([0-9.e]+)\)", steps[0]).groups())
    assert len(f.forms) == 1 and abs(tc - 40.0) < 0.005 and w <= 0.01, f.forms
    # the term's drift change at the peak is the step's
    assert abs(f.amplitude) == pytest.approx(0.4, rel=0.25), f
