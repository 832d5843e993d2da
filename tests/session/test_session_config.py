"""The per-gyro ``lkf`` section of a session file: values, warm-up defaults, key-path errors."""

from __future__ import annotations

import copy

import pytest
from sessionhelpers import DEMO, demo_dict

from gyrostand.config import LkfConfig, parse_config
from gyrostand.errors import ConfigError
from gyrostand.session.online import GyroTracker


def _cfg(lkf):
    d = copy.deepcopy(demo_dict())
    d["gyros"][0]["lkf"] = lkf
    return parse_config(d, source="t.yaml", base_dir=DEMO.parent)


def test_lkf_section_values_and_defaults():
    g = _cfg({"beta0": 0.03, "gamma0": -0.001, "sigma": 0.1, "white_sigma": 0.0,
              "b0": "auto", "warmup": 120, "iterate": True}).gyros[0]
    assert g.lkf == LkfConfig(0.03, -0.001, None, 0.1, 0.0, {}, 120, True)
    assert g.lkf.needs_warmup  # b0 left to the data
    assert parse_config(demo_dict(), "t.yaml", DEMO.parent).gyros[0].lkf == LkfConfig()
    # everything given: the online LKF starts at the first bin, no warm-up
    full = _cfg({"beta0": 0.03, "gamma0": -0.001, "b0": 0.0, "sigma": 0.1,
                 "white_sigma": 0.01}).gyros[0]
    tr = GyroTracker(full, 1.0)
    tr.update(0.5, 20.0)
    (lkf, lsq) = tr.estimates()
    # one bin: started at once, but honest: β's ±3σ band still contains 0
    assert lkf.status == "warning" and "contains 0" in lkf.note
    assert lkf.values["white.sigma"] == (0.01, 0.0)
    assert lsq.status == "insufficient_data"


@pytest.mark.parametrize("lkf, match", [
    ({"beta0": 0}, r"t\.yaml: gyros\[0\]\.lkf\.beta0: must be > 0"),
    ({"sigma": -1}, r"gyros\[0\]\.lkf\.sigma: must be > 0"),
    ({"gamma": 1}, r"gyros\[0\]\.lkf\.gamma: unknown key"),
    ({"held": {"random_walk.q": 1}}, r"gyros\[0\]\.lkf\.held\.random_walk\.q: expected"),
    ({"warmup": 5}, r"gyros\[0\]\.lkf\.warmup: must be in \[10, "),
    ({"iterate": "yes"}, r"gyros\[0\]\.lkf\.iterate: expected true or false"),
])
def test_lkf_section_errors_name_the_key(lkf, match):
    with pytest.raises(ConfigError, match=match):
        _cfg(lkf)


def test_lkf_warm_up_gives_up_with_bounded_memory():
    g = _cfg({"warmup": 10}).gyros[0]
    tr = GyroTracker(g, 1.0)
    for _ in range(250):  # a constant drift at a constant temperature: nothing to fit
        tr.update(0.5, 20.0)
    lkf = tr.estimates()[0]
    assert lkf.status == "failed" and "no usable warm-up within 201 bins" in lkf.note
    tr.reset()
    assert tr.estimates()[0].status == "insufficient_data"


def test_the_loader_asks_each_identifier_whether_it_can_identify_the_model(caplog):
    """``run --check`` refuses an identifier the model is beyond (lsq and temp_rate: least
    squares' regression has no such column), naming the key and the term, instead of a run
    whose lsq is refused at every bin; left to the defaults, the identifier is dropped
    with a warning and the others run."""
    d = copy.deepcopy(demo_dict())
    d["gyros"][0]["model"] = ["markov", "temp", "temp_rate"]
    d["gyros"][0]["identifiers"] = ["lkf", "lsq"]
    with pytest.raises(ConfigError, match=r"t\.yaml: gyros\[0\]\.identifiers: lsq cannot "
                                          r"identify this model: lsq does not support the "
                                          r"term\(s\) temp_rate; use ml"):
        parse_config(d, source="t.yaml", base_dir=DEMO.parent)
    d["gyros"][0]["identifiers"] = ["lkf"]
    assert parse_config(d, "t.yaml", DEMO.parent).gyros[0].identifiers == ("lkf",)
    del d["gyros"][0]["identifiers"]
    with caplog.at_level("WARNING"):
        g = parse_config(d, "t.yaml", DEMO.parent).gyros[0]
    assert g.identifiers == ("lkf",)
    assert "lsq cannot identify the model (markov, temp, temp_rate)" in caplog.text
