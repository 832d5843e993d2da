"""Bad input gives a clear error naming the file and line, or a warning: never a silent NaN."""

import numpy as np
import pytest

from gyrostand.core.data import Samples
from gyrostand.core.identify import identify
from gyrostand.core.model import Model
from gyrostand.core.profiles import paper_profile
from gyrostand.core.simulate import simulate
from gyrostand.errors import DataError, IdentificationError


def write(tmp_path, text, name="s.csv"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_reads_a_plain_csv(tmp_path):
    p = write(tmp_path, "t,drift,temp,n_drift\n0,0.5,20,10\n1,0.6,20.1,10\n2,0.7,20.2,9\n")
    s = Samples.read_csv(p)
    np.testing.assert_array_equal(s.drift, [0.5, 0.6, 0.7])
    assert s.dt == 1.0 and s.warnings == ()


def test_missing_columns_are_named(tmp_path):
    p = write(tmp_path, "time,drift\n0,1\n")
    with pytest.raises(DataError, match=r"s\.csv: line 1: missing column\(s\) t, temp"):
        Samples.read_csv(p)


def test_non_numeric_cell_names_file_line_and_column(tmp_path):
    p = write(tmp_path, "t,drift,temp\n0,1,20\n1,abc,20\n")
    with pytest.raises(DataError, match=r"s\.csv: line 3: column drift: 'abc' is not a number"):
        Samples.read_csv(p)


def test_backwards_time_is_an_error_with_line(tmp_path):
    p = write(tmp_path, "t,drift,temp\n0,1,20\n2,1,20\n1,1,20\n")
    with pytest.raises(DataError, match=r"line 4: time goes backwards \(t = 1 s after 2 s\)"):
        Samples.read_csv(p)


def test_duplicated_time_is_an_error_with_line(tmp_path):
    p = write(tmp_path, "t,drift,temp\n0,1,20\n1,1,20\n1,2,20\n")
    with pytest.raises(DataError, match=r"line 4: duplicated time t = 1 s"):
        Samples.read_csv(p)


def test_empty_t_is_an_error(tmp_path):
    p = write(tmp_path, "t,drift,temp\n0,1,20\n,1,20\n")
    with pytest.raises(DataError, match="line 3: column t is empty"):
        Samples.read_csv(p)


def test_off_grid_time_is_an_error(tmp_path):
    p = write(tmp_path, "t,drift,temp\n0,1,20\n1,1,20\n2.5,1,20\n")
    with pytest.raises(DataError, match="line 4: t = 2.5 s is not on the 1-s grid .*--dt"):
        Samples.read_csv(p)


def test_nan_rows_become_gaps_with_warnings(tmp_path):
    p = write(tmp_path, "t,drift,temp\n0,1,20\n1,nan,nan\n2,,20.4\n4,1.5,20.8\n")
    s = Samples.read_csv(p)
    assert len(s) == 5  # t = 3 was missing: a gap
    assert np.isnan(s.drift[[1, 2, 3]]).all()
    np.testing.assert_allclose(s.temp, [20, 20.2, 20.4, 20.6, 20.8])
    assert any("missing time steps" in w for w in s.warnings)
    assert any("interpolated" in w for w in s.warnings)


def test_all_nan_drift_is_an_error(tmp_path):
    p = write(tmp_path, "t,drift,temp\n0,nan,20\n1,nan,21\n")
    with pytest.raises(DataError, match="no finite drift values"):
        Samples.read_csv(p)


def test_empty_file_and_header_only(tmp_path):
    with pytest.raises(DataError, match="empty file"):
        Samples.read_csv(write(tmp_path, ""))
    with pytest.raises(DataError, match="no data rows"):
        Samples.read_csv(write(tmp_path, "t,drift,temp\n"))


def test_missing_file_is_a_data_error(tmp_path):
    with pytest.raises(DataError, match="cannot open"):
        Samples.read_csv(tmp_path / "nope.csv")


@pytest.mark.parametrize("method", ["lsq", "lkf", "ml"])
def test_fewer_samples_than_parameters(method):
    t = np.arange(4.0)
    s = Samples.from_arrays(t, [0.1, 0.2, 0.1, 0.3], [20, 21, 22, 23])
    with pytest.raises(DataError, match=f"{method} needs at least \\d+ usable samples"):
        identify(s, Model.parse("markov,temp,bias"), method)


def test_constant_temperature_is_flagged_by_every_identifier():
    m = Model.parse("markov,temp,bias")
    p = {"markov.beta": 0.03, "markov.sigma": 0.1, "temp.gamma": -0.01, "white.sigma": 0.01,
         "bias.b": 0.2}
    t = np.arange(2000.0)
    s = simulate(m, p, t=t, temp=np.full(t.size, 25.0), seed=1)
    assert any("temperature is constant" in w for w in s.warnings)
    with pytest.raises(IdentificationError, match="temperature is constant"):
        identify(s, m, "lsq")
    r = identify(s, m, "ml")
    assert any("temperature is constant" in w for w in r.warnings)
    assert any("not identifiable" in w and "temp.gamma" in w for w in r.warnings)
    assert all(np.isfinite(e.value) and np.isfinite(e.std) for e in r.parameters.values())
    r = identify(s, m, "lkf")
    assert any("temperature is constant" in w for w in r.warnings)
    assert all(np.isfinite(e.value) and np.isfinite(e.std) for e in r.parameters.values())


@pytest.mark.parametrize("method", ["lsq", "lkf", "ml"])
def test_gaps_never_produce_nan_estimates(method):
    m = Model.parse("markov,temp,bias")
    p = {"markov.beta": 0.03, "markov.sigma": 0.1, "temp.gamma": -0.01, "white.sigma": 0.01,
         "bias.b": 0.2}
    s = simulate(m, p, paper_profile(), seed=2)
    y = s.drift.copy()
    y[300:420] = np.nan
    y[::37] = np.nan
    opts = {"iterate": True} if method == "lkf" else {}
    r = identify(Samples.from_arrays(s.t, y, s.temp), m, method, **opts)
    for e in r.parameters.values():
        assert np.isfinite(e.value) and np.isfinite(e.std)
    assert np.isnan(r.residuals[300:420]).all()
    assert abs(r.value("temp.gamma") / -0.01 - 1) < 0.5
