"""Bad input gives a clear error naming the file and line, or a warning: never a silent NaN."""

import numpy as np
import pytest

from gyrostand.core.data import Samples
from gyrostand.core.model import Model
from gyrostand.core.profiles import paper_profile
from gyrostand.core.registry import identify
from gyrostand.core.simulation import simulate
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


# ---- CSV input as people write it -------------------------------------------------------

def test_a_utf8_bom_csv_reads(tmp_path):
    p = tmp_path / "bom.csv"
    p.write_bytes("\ufefft,drift,temp\n0,1,20\n1,1.1,20.1\n".encode())
    s = Samples.read_csv(p)
    assert len(s) == 2 and s.drift[1] == 1.1


@pytest.mark.parametrize("data, what", [
    ("t,drift,temp\n0,1,20\n".encode("utf-16"), "UTF-16 text"),
    (b"t,drift,temp\n0,1,20\n1,\xe9,20\n", "line 3: not UTF-8 text"),
    (b"t,drift,temp\n0,1,20\x00\n", "line 2: a NUL character"),
])
def test_non_utf8_csvs_give_a_clean_error(tmp_path, data, what):
    p = tmp_path / "bad.csv"
    p.write_bytes(data)
    with pytest.raises(DataError, match=f"bad.csv: {what}"):
        Samples.read_csv(p)


def test_missing_rows_are_gaps_at_the_most_common_step(tmp_path):
    rows = [0, 2, 4, 6, 10, 12, 14, 20, 22]  # 2-s record with missing rows
    p = write(tmp_path, "t,drift,temp\n" + "".join(f"{t},{t * 0.1},{20 + t}\n" for t in rows))
    s = Samples.read_csv(p)
    assert s.dt == 2.0 and len(s) == 12
    assert np.isnan(s.drift[[4, 8, 9]]).all() and s.n_observed == 9
    assert Samples.read_csv(p, dt=1.0).dt == 1.0


def test_epoch_times_with_one_early_row_keep_their_step(tmp_path):
    t0 = 1_700_000_000.0
    t = t0 + np.arange(50.0)
    t[20] -= 0.1  # one row 0.1 s early
    p = write(tmp_path, "t,drift,temp\n" + "".join(f"{float(x)!r},{i * 0.01},20\n" for i, x in
                                                    enumerate(t)))
    s = Samples.read_csv(p)
    assert s.dt == 1.0 and len(s) == 50 and s.n_observed == 50
    assert any("1 rows off the 1-s grid (up to 0.1 s, first at" in w and "line 22" in w
               for w in s.warnings), s.warnings


def test_an_irregular_cadence_snaps_to_its_own_step(tmp_path):
    rng = np.random.default_rng(0)
    t = 1_440_000_000 + np.concatenate([[0], np.cumsum(rng.choice([9, 10, 11], 300))])
    t = t[np.abs(t - t[0] - 10 * np.rint((t - t[0]) / 10)) <= 2]  # what the record keeps
    p = write(tmp_path, "t,drift,temp\n" + "".join(f"{x},0.1,20\n" for x in t))
    s = Samples.read_csv(p)
    assert s.dt == 10.0 and s.n_observed + sum(
        int(w.split()[0]) for w in s.warnings if "shared a bin" in w) == t.size


@pytest.mark.parametrize("jump", [1e9, 1e7])
def test_a_timestamp_typo_is_an_error_naming_the_line(tmp_path, jump):
    t = list(range(100)) + [99 + jump]
    p = write(tmp_path, "t,drift,temp\n" + "".join(f"{x:.0f},0.1,20\n" for x in t))
    with pytest.raises(DataError, match=r"line 102: time jumps by .* a timestamp typo\?"):
        Samples.read_csv(p)


def test_spikes_are_caught_next_to_gaps_and_as_two_sample_jolts():
    from gyrostand.core.validate import find_spikes

    rng = np.random.default_rng(1)
    y = rng.standard_normal(400)
    y[[99, 101]] = np.nan
    y[100] = 80.0  # a spike with gaps on both sides
    y[250], y[251] = -60.0, 55.0  # a jolt: a swing and its rebound
    y[300:] += 70.0  # a step is no spike
    assert list(find_spikes(y)) == [100, 250, 251]


def test_a_1_hz_logger_with_jitter_is_on_its_1_s_grid(tmp_path):
    """Issue 28: rows at 1 Hz ± 0.05 s (steps of 0.9 and 1.1 s) are on the 1-s grid, not
    'not on the 1.1-s grid'; each row lands in its own bin."""
    rows = "".join(f"{k + (0.05 if k % 2 else -0.05):.3f},{0.1 + 0.001 * k},25\n"
                   for k in range(200))
    s = Samples.read_csv(write(tmp_path, "t,drift,temp\n" + rows))
    assert s.dt == 1.0 and len(s) == 200 and np.isfinite(s.drift).all()
    np.testing.assert_allclose(s.drift, 0.1 + 0.001 * np.arange(200))


def test_errors_name_epoch_times_with_every_digit_and_the_date(tmp_path):
    """Issue 28: 't = 1.7e+09 s' named no row a person can find."""
    rows = "".join(f"{1733300000 + k},0.1,25\n" for k in range(20))
    p = write(tmp_path, "t,drift,temp\n" + rows + "1733300010.5,0.1,25\n")
    with pytest.raises(DataError, match=r"t = 1733300010.5 s \(2024-12-04 08:13:30.5 UTC\) "
                                        r"after 1733300019 s"):
        Samples.read_csv(p)


def test_a_logger_clock_slightly_off_keeps_its_own_step(tmp_path):
    """The jitter rule's round step (1 s) is taken only where the rows lie on its grid: a
    clock 0.04 % fast over 2000 rows keeps its 1.0004-s step (a 1-s grid is 0.8 s off)."""
    rows = "".join(f"{k * 1.0004:.4f},0.1,25\n" for k in range(2000))
    s = Samples.read_csv(write(tmp_path, "t,drift,temp\n" + rows))
    assert s.dt == pytest.approx(1.0004, abs=1e-9) and len(s) == 2000
