"""Binned samples: the 1-s series every identifier works on.

A :class:`Samples` holds a uniform time grid ``t`` (s), the drift ``drift`` (the gyro's
unit, e.g. deg/h; NaN marks an empty bin, a *gap*), and the built-in sensor's temperature
``temp`` (degC, interpolated over gaps so the model's input stays defined). It is built
either from arrays or from a CSV with a header naming at least the columns ``t, drift,
temp``. Validation never lets a NaN pass silently: a bad value is an error that names the
file and line, a repairable one (a gap) becomes a warning carried with the samples.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import DataError

REQUIRED_COLUMNS = ("t", "drift", "temp")

#: temperature span (degC) below which beta and gamma cannot be told apart
MIN_TEMP_SPAN = 0.05


@dataclass(frozen=True)
class Samples:
    """A uniform series of binned samples.

    Attributes:
        t: sample times, s, shape (N,), strictly increasing with constant step ``dt``.
        drift: measured drift, shape (N,); NaN where the bin was empty (a gap).
        temp: measured temperature, degC, shape (N,); finite everywhere.
        dt: sampling step, s.
        source: provenance (file path or a description).
        warnings: what validation repaired or noticed.
    """

    t: np.ndarray
    drift: np.ndarray
    temp: np.ndarray
    dt: float
    source: str = "arrays"
    warnings: tuple[str, ...] = field(default_factory=tuple)

    def __len__(self) -> int:
        return int(self.t.size)

    @property
    def n_observed(self) -> int:
        """Number of bins with a drift measurement."""
        return int(np.count_nonzero(np.isfinite(self.drift)))

    @property
    def temp_span(self) -> float:
        """Peak-to-peak temperature, degC."""
        return float(np.max(self.temp) - np.min(self.temp))

    @classmethod
    def from_arrays(
        cls,
        t: np.ndarray,
        drift: np.ndarray,
        temp: np.ndarray,
        *,
        dt: float | None = None,
        source: str = "arrays",
        lines: np.ndarray | None = None,
    ) -> Samples:
        """Validate arrays and return samples on a uniform grid.

        ``t`` must be finite and strictly increasing; its steps must be whole multiples of
        ``dt`` (default: the smallest step), missing grid points become gaps. NaN drift is a
        gap; NaN temperature is interpolated from its neighbours (a warning says how many).
        ``lines`` (file line of each row) lets errors point into the source file.
        """
        t = np.asarray(t, dtype=float)
        drift = np.asarray(drift, dtype=float)
        temp = np.asarray(temp, dtype=float)
        if not (t.shape == drift.shape == temp.shape) or t.ndim != 1:
            raise DataError(f"{source}: t, drift and temp must be 1-D arrays of one length")

        def where(i: int) -> str:
            return f"{source}: line {int(lines[i])}" if lines is not None else f"{source}: row {i}"

        if t.size == 0:
            raise DataError(f"{source}: no samples")
        bad = np.flatnonzero(~np.isfinite(t))
        if bad.size:
            raise DataError(f"{where(bad[0])}: time t is not a finite number")
        steps = np.diff(t)
        bad = np.flatnonzero(steps == 0)
        if bad.size:
            raise DataError(f"{where(bad[0] + 1)}: duplicated time t = {t[bad[0] + 1]:g} s")
        bad = np.flatnonzero(steps < 0)
        if bad.size:
            i = bad[0] + 1
            raise DataError(
                f"{where(i)}: time goes backwards (t = {t[i]:g} s after {t[i - 1]:g} s); "
                "samples must be in increasing time order"
            )
        bad = np.flatnonzero(np.isinf(drift) | np.isinf(temp))
        if bad.size:
            raise DataError(f"{where(bad[0])}: infinite drift or temperature")
        warnings: list[str] = []
        if dt is None:
            dt = float(np.min(steps)) if steps.size else 1.0
        if not (dt > 0 and math.isfinite(dt)):
            raise DataError(f"{source}: sampling step dt must be positive, got {dt!r}")
        if steps.size:
            k = np.rint((t - t[0]) / dt)
            off = np.abs((t - t[0]) - k * dt)
            bad = np.flatnonzero(off > 1e-6 * dt + 1e-9 * abs(t[0]))
            if bad.size:
                raise DataError(
                    f"{where(bad[0])}: t = {t[bad[0]]:g} s is not on the {dt:g}-s grid "
                    f"started at {t[0]:g} s; resample the data to a uniform step"
                )
            n = int(k[-1]) + 1
            if n != t.size:
                full_d = np.full(n, np.nan)
                full_T = np.full(n, np.nan)
                idx = k.astype(int)
                full_d[idx] = drift
                full_T[idx] = temp
                warnings.append(
                    f"{n - t.size} missing time steps filled as gaps (no drift measured there)"
                )
                drift, temp = full_d, full_T
                t = t[0] + dt * np.arange(n)
        n_gap = int(np.count_nonzero(np.isnan(drift)))
        if n_gap and not any("missing time steps" in w for w in warnings):
            warnings.append(f"{n_gap} samples with NaN drift treated as gaps")
        if np.all(np.isnan(drift)):
            raise DataError(f"{source}: no finite drift values")
        nan_T = np.isnan(temp)
        if nan_T.all():
            raise DataError(f"{source}: no finite temperature values")
        if nan_T.any():
            good = np.flatnonzero(~nan_T)
            temp = temp.copy()
            temp[nan_T] = np.interp(np.flatnonzero(nan_T), good, temp[good])
            warnings.append(f"{int(nan_T.sum())} missing temperatures interpolated linearly")
        span = float(np.max(temp) - np.min(temp))
        if span < MIN_TEMP_SPAN:
            warnings.append(
                f"temperature is constant (span {span:.3g} degC): the temperature "
                "coefficient cannot be told apart from a bias or from beta"
            )
        for a in (t, drift, temp):
            a.setflags(write=False)
        return cls(t=t, drift=drift, temp=temp, dt=float(dt), source=source,
                   warnings=tuple(warnings))

    @classmethod
    def read_csv(cls, path: str | Path, *, dt: float | None = None) -> Samples:
        """Read a CSV with a header containing ``t``, ``drift`` and ``temp`` columns.

        Extra columns (e.g. ``n_drift``) are ignored. Empty or ``nan`` cells in drift/temp
        are gaps; anything else unparsable is an error naming the file and line. A last
        line without its line end and with fewer cells than the header is torn (a writer
        stopped mid-line, e.g. a daemon killed while appending): it is left out, with a
        warning.
        """
        path = Path(path)
        torn = _torn_last_line(path)
        try:
            fh = path.open(newline="")
        except OSError as exc:
            raise DataError(f"{path}: cannot open: {exc.strerror}") from exc
        with fh:
            reader = csv.reader(fh)
            header = next(reader, None)
            if header is None:
                raise DataError(f"{path}: empty file (expected a header t,drift,temp)")
            names = [h.strip() for h in header]
            missing = [c for c in REQUIRED_COLUMNS if c not in names]
            if missing:
                raise DataError(
                    f"{path}: line 1: missing column(s) {', '.join(missing)} "
                    f"(header has: {', '.join(names) or 'nothing'})"
                )
            cols = [names.index(c) for c in REQUIRED_COLUMNS]
            rows: list[tuple[float, float, float]] = []
            lines: list[int] = []
            body = list(reader)
            torn = torn and bool(body) and len(body[-1]) < len(names)
            if torn:
                body.pop()
            for lineno, row in enumerate(body, start=2):
                if not row or all(not c.strip() for c in row):
                    continue
                vals = []
                for c, name in zip(cols, REQUIRED_COLUMNS, strict=True):
                    cell = row[c].strip() if c < len(row) else ""
                    if cell == "" or cell.lower() == "nan":
                        if name == "t":
                            raise DataError(f"{path}: line {lineno}: column t is empty")
                        vals.append(math.nan)
                        continue
                    try:
                        vals.append(float(cell))
                    except ValueError:
                        raise DataError(
                            f"{path}: line {lineno}: column {name}: {cell!r} is not a number"
                        ) from None
                rows.append((vals[0], vals[1], vals[2]))
                lines.append(lineno)
        if not rows:
            raise DataError(f"{path}: no data rows after the header")
        arr = np.array(rows)
        s = cls.from_arrays(arr[:, 0], arr[:, 1], arr[:, 2], dt=dt, source=str(path),
                            lines=np.array(lines))
        if torn:
            note = f"{path}: torn last line (no line end) left out"
            s = cls(t=s.t, drift=s.drift, temp=s.temp, dt=s.dt, source=s.source,
                    warnings=(*s.warnings, note))
        return s

    def to_csv(self, path: str | Path) -> None:
        """Write ``t, drift, temp`` (gaps as empty drift cells) to ``path``."""
        with Path(path).open("w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(REQUIRED_COLUMNS)
            for a, b, c in zip(self.t, self.drift, self.temp, strict=True):
                w.writerow((repr(float(a)), "" if math.isnan(b) else repr(float(b)),
                            repr(float(c))))


def _torn_last_line(path: Path) -> bool:
    """True when the file is not empty and does not end with a line end."""
    try:
        with path.open("rb") as fh:
            fh.seek(0, 2)
            if fh.tell() == 0:
                return False
            fh.seek(-1, 2)
            return fh.read(1) not in (b"\n", b"\r")
    except OSError:
        return False
