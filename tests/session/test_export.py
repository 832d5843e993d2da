"""``gyrostand export RUN --parquet / --mf4``: a replayed run's samples and online
estimates read back with pyarrow and asammdf equal the CSVs, value for value, with the
DBC's units and the model's parameter units."""

from __future__ import annotations

import datetime as dt
import sys

import numpy as np
import pytest
from sessionhelpers import write_cfg_yaml

from gyrostand import exitcodes
from gyrostand.can.framesim import write_log
from gyrostand.cli import main
from gyrostand.config import load_config
from gyrostand.runfolder import SAMPLES_COLUMNS, read_estimates_csv, read_samples_csv
from gyrostand.session.export import ExportError, export_parquet
from gyrostand.session.offline import run_replay, simulated_frames

pa = pytest.importorskip("pyarrow")
pq = pytest.importorskip("pyarrow.parquet")
asammdf = pytest.importorskip("asammdf")


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("export")
    cfg_path = write_cfg_yaml(tmp / "s.yaml", tmp / "runs",
                              {"interface": "virtual", "channel": "export-test"},
                              duration=400.0, rates={"drift": 20, "temperature": 10})
    cfg = load_config(cfg_path)
    log = tmp / "sim.blf"
    write_log(log, simulated_frames(cfg))
    outcome = run_replay(cfg, log, out=tmp / "runs")
    return outcome.run_dir


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    return a.dtype.kind == b.dtype.kind and np.array_equal(a, b, equal_nan=a.dtype.kind == "f")


def test_parquet_round_trip(run_dir, tmp_path, capsys):
    assert main(["export", str(run_dir), "--parquet", "--out", str(tmp_path)]) == 0
    assert capsys.readouterr().out.split() == [
        "wrote", str(tmp_path / "az" / "samples.parquet"),
        "wrote", str(tmp_path / "az" / "estimates.parquet")]
    samples = pq.read_table(tmp_path / "az" / "samples.parquet")
    csv = read_samples_csv(run_dir / "az" / "samples.csv")
    assert samples.column_names == list(SAMPLES_COLUMNS) and samples.num_rows == 401
    for k in SAMPLES_COLUMNS:
        want = np.asarray(csv[k], dtype=np.int64 if k.startswith("n_") else float)
        assert _same(samples.column(k).to_numpy(), want), k
    units = {f.name: f.metadata[b"unit"].decode() for f in samples.schema}
    assert units == {"t": "s", "drift": "deg/h", "temp": "degC", "n_drift": "",
                     "n_temp": ""}
    assert samples.schema.metadata[b"gyro"] == b"az"
    est = pq.read_table(tmp_path / "az" / "estimates.parquet")
    cols = read_estimates_csv(run_dir / "az" / "estimates.csv")
    assert est.column_names == list(cols) and est.num_rows == len(cols["t"]) == 401
    for k, v in cols.items():
        got = est.column(k)
        if k.endswith(":status"):
            assert got.to_pylist() == v and pa.types.is_dictionary(got.type)
        else:
            assert _same(got.to_numpy(), np.asarray(v, dtype=float)), k
    eu = {f.name: f.metadata[b"unit"].decode() for f in est.schema}
    assert eu["lkf:markov.beta"] == eu["lkf:markov.beta:std"] == "1/s"
    assert eu["lsq:temp.gamma"] == "(deg/h)/(s·°C)" and eu["lkf:markov.sigma"] == "deg/h"


def test_parquet_units_visible_to_pandas(run_dir, tmp_path):
    """pandas drops pyarrow's field metadata: the units also travel as pandas' attrs
    (``PANDAS_ATTRS``), which ``pd.read_parquet`` restores; column names are unchanged and
    pyarrow reads the same map, equal to the fields' ``unit``."""
    import json

    pd = pytest.importorskip("pandas")
    assert main(["export", str(run_dir), "--parquet", "--out", str(tmp_path)]) == 0
    for kind in ("samples", "estimates"):
        path = tmp_path / "az" / f"{kind}.parquet"
        df = pd.read_parquet(path)
        table = pq.read_table(path)
        assert list(df.columns) == table.column_names
        fields = {f.name: f.metadata[b"unit"].decode() for f in table.schema}
        assert df.attrs["units"] == fields
        assert {k: df.attrs[k] for k in ("gyro", "run", "table")} == {
            "gyro": "az", "run": run_dir.name, "table": kind}
        assert json.loads(table.schema.metadata[b"PANDAS_ATTRS"]) == df.attrs
    units = pd.read_parquet(tmp_path / "az" / "samples.parquet").attrs["units"]
    assert units == {"t": "s", "drift": "deg/h", "temp": "degC", "n_drift": "",
                     "n_temp": ""}
    est = pd.read_parquet(tmp_path / "az" / "estimates.parquet")
    assert est.attrs["units"]["lsq:temp.gamma"] == "(deg/h)/(s·°C)"
    assert est.attrs["units"]["lkf:markov.beta:std"] == "1/s"
    assert est.attrs["units"]["lkf:status"] == ""


def test_result_json_carries_the_units_of_its_numbers(run_dir):
    """Units in every document (issue 27): result.json's gyro has the units the Parquet
    export's fields carry, each parameter's as the tables print it."""
    import json

    units = json.loads((run_dir / "result.json").read_text())["gyros"]["az"]["units"]
    assert {k: units[k] for k in ("drift", "temp", "t")} == {
        "drift": "deg/h", "temp": "degC", "t": "s"}
    assert units["parameters"]["temp.gamma"] == "(deg/h)/(s·°C)"
    assert units["parameters"]["markov.beta"] == "1/s"
    assert units["parameters"]["markov.sigma"] == "deg/h"


def test_mf4_round_trip(run_dir, tmp_path, capsys):
    assert main(["export", str(run_dir), "--mf4", "--out", str(tmp_path)]) == 0
    path = tmp_path / f"{run_dir.name}.mf4"
    assert capsys.readouterr().out.strip() == f"wrote {path}"
    csv = read_samples_csv(run_dir / "az" / "samples.csv")
    cols = read_estimates_csv(run_dir / "az" / "estimates.csv")
    t0 = csv["t"][0]
    with asammdf.MDF(path) as mdf:
        assert mdf.version == "4.10"
        start = mdf.header.start_time
        assert start == dt.datetime.fromtimestamp(t0, tz=dt.UTC)
        for k, unit in (("drift", "deg/h"), ("temp", "degC"), ("n_drift", ""),
                        ("n_temp", "")):
            sig = mdf.get(f"az.{k}")
            assert sig.unit == unit
            assert np.array_equal(sig.samples, np.asarray(csv[k]), equal_nan=True), k
            assert np.array_equal(sig.timestamps, np.asarray(csv["t"]) - t0)
        for k, v in cols.items():
            if k == "t":
                continue
            sig = mdf.get("az." + k.replace(":", "."))
            if k.endswith(":status"):
                assert [s.decode() for s in sig.samples] == v, k
            else:
                assert np.array_equal(sig.samples, np.asarray(v), equal_nan=True), k
                assert np.array_equal(sig.timestamps, np.asarray(cols["t"]) - t0)
        assert mdf.get("az.lkf.temp.gamma").unit == "(deg/h)/(s·°C)"
        assert mdf.get("az.ml.markov.beta" if "ml:markov.beta" in cols
                       else "az.lkf.markov.beta.std").unit == "1/s"


def test_errors(run_dir, tmp_path, capsys, monkeypatch):
    assert main(["export", str(run_dir)]) == exitcodes.USAGE
    assert "choose a format: --parquet and/or --mf4" in capsys.readouterr().err
    assert main(["export", str(tmp_path), "--parquet"]) == exitcodes.NOINPUT
    assert "not a run folder (no result.json)" in capsys.readouterr().err
    assert main(["export", str(run_dir), "--parquet", "--gyro", "zz"]) == exitcodes.DATAERR
    assert "no gyro 'zz' (the run has az)" in capsys.readouterr().err
    monkeypatch.setitem(sys.modules, "pyarrow", None)  # as if not installed
    with pytest.raises(ExportError, match=r"pip install 'gyrostand\[formats\]'"):
        export_parquet(run_dir, tmp_path)


# ---- the run itself writes them (session.formats, --data-format) -----------------------

def _fixture_files(run_dir):
    """The fixture's session file and simulated log (beside its runs/ folder)."""
    top = run_dir.parents[1]
    return top / "s.yaml", top / "sim.blf"


def test_replay_with_data_format_parquet_writes_it_beside_identical_csvs(run_dir, tmp_path,
                                                                          capsys):
    cfg, log = _fixture_files(run_dir)
    assert main(["replay", str(cfg), str(log), "--out", str(tmp_path),
                 "--data-format", "parquet"]) == 0
    capsys.readouterr()
    (new,) = [p for p in tmp_path.iterdir() if p.is_dir()]
    for name in ("samples.csv", "estimates.csv"):  # the CSVs as without the option
        assert (new / "az" / name).read_bytes() == (run_dir / "az" / name).read_bytes(), name
    samples = pq.read_table(new / "az" / "samples.parquet")
    csv = read_samples_csv(new / "az" / "samples.csv")
    assert samples.num_rows == len(csv["t"]) == 401
    for k in SAMPLES_COLUMNS:
        want = np.asarray(csv[k], dtype=np.int64 if k.startswith("n_") else float)
        assert _same(samples.column(k).to_numpy(), want), k
    est = pq.read_table(new / "az" / "estimates.parquet")
    cols = read_estimates_csv(new / "az" / "estimates.csv")
    assert est.column_names == list(cols)
    for k, v in cols.items():
        got = est.column(k).to_pylist() if k.endswith(":status") else est.column(k).to_numpy()
        if k.endswith(":status"):
            assert got == list(v), k
        else:
            assert _same(np.asarray(got), np.asarray(v, dtype=float)), k
    assert not (new / f"{new.name}.mf4").exists()  # only what was asked for


def test_session_formats_key_writes_parquet_and_mf4(run_dir, tmp_path):
    import yaml

    cfg_path, log = _fixture_files(run_dir)
    d = yaml.safe_load(cfg_path.read_text())
    d["session"]["formats"] = ["parquet", "mf4"]
    path = tmp_path / "s.yaml"
    path.write_text(yaml.safe_dump(d))
    cfg = load_config(path)
    assert cfg.formats == ("parquet", "mf4")
    out = run_replay(cfg, log, out=tmp_path / "runs")
    assert out.ok and not out.stats["unwritten"]
    assert (out.run_dir / "az" / "samples.parquet").is_file()
    assert (out.run_dir / "az" / "estimates.parquet").is_file()
    with asammdf.MDF(out.run_dir / f"{out.run_dir.name}.mf4") as mdf:
        drift = mdf.get("az.drift")
    csv = read_samples_csv(out.run_dir / "az" / "samples.csv")
    assert np.array_equal(drift.samples, np.asarray(csv["drift"], dtype=float), equal_nan=True)


def test_bad_formats_are_config_errors_naming_the_key(run_dir, tmp_path, monkeypatch,
                                                       capsys):
    import yaml

    from gyrostand.errors import ConfigError

    cfg_path, _ = _fixture_files(run_dir)
    d = yaml.safe_load(cfg_path.read_text())
    d["session"]["formats"] = ["parquet", "csv"]
    path = tmp_path / "s.yaml"
    path.write_text(yaml.safe_dump(d))
    with pytest.raises(ConfigError, match=r"session\.formats\[1\]: 'csv' is not one of: "
                                          r"parquet, mf4"):
        load_config(path)
    # a package that is not installed: said when the session is loaded, not at the run's end
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *a: None if name == "pyarrow" else real(name, *a))
    d["session"]["formats"] = ["parquet"]
    path.write_text(yaml.safe_dump(d))
    with pytest.raises(ConfigError, match=r"session\.formats: parquet needs the pyarrow "
                                          r"package .*gyrostand\[formats\]"):
        load_config(path)
    capsys.readouterr()
    assert main(["replay", str(cfg_path), str(tmp_path / "none.blf"), "--data-format",
                 "parquet"]) == exitcodes.CONFIG
    assert "error: --data-format: parquet needs the pyarrow package" in capsys.readouterr().err
