"""Backward check of an adequate model (issue 23): a term an earlier step added that the
data no longer need is named, with the fit --remove advice."""

from __future__ import annotations

import numpy as np

from gyrostand.core.data import Samples
from gyrostand.core.diagnose.verdict import diagnose
from gyrostand.core.model import Model
from gyrostand.core.profiles import chamber_profile
from gyrostand.core.simulation import simulate
from gyrostand.report.text import diagnosis

BASE = {"markov.beta": 0.01, "markov.sigma": 0.05, "temp.gamma": -0.0005,
        "white.sigma": 0.02, "bias.b": 0.3, "temp2.gamma2": 5e-6}


def test_an_adequate_model_names_the_term_it_does_not_need():
    s = simulate(Model.parse("markov,temp,bias,temp2"), BASE, chamber_profile(2.0), seed=4)
    rng = np.random.default_rng(5)
    temp = np.round((s.temp + 0.01 * rng.standard_normal(len(s))) / 0.05) * 0.05
    s = Samples.from_arrays(s.t, s.drift, temp)
    rep = diagnose(s, Model.parse("markov,temp,bias,temp2,random_walk"))
    assert rep.adequate, rep.reasons
    names = [x["term"] for x in rep.redundant]
    assert names == ["random_walk"], rep.redundant  # temp2 is real: it stays
    x = rep.redundant[0]
    assert x["p_value"] >= 0.05 and x["test"] == "chi2 mixture"
    text = diagnosis(rep, "run.csv", fit_command="gyrostand fit run.csv")
    assert "redundant: random_walk no longer earns its place" in text
    assert "next: gyrostand fit run.csv --remove random_walk" in text
    assert rep.to_dict()["redundant"][0]["term"] == "random_walk"
