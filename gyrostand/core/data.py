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
import dataclasses
import datetime as _dt
import io
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import DataError

REQUIRED_COLUMNS = ("t", "drift", "temp")

#: temperature span (degC) below which beta and gamma cannot be told apart
MIN_TEMP_SPAN = 0.05

#: a grid longer than this many times the rows (and than MIN_GRID_LIMIT) is a typo
MAX_GRID_FACTOR = 20
MIN_GRID_LIMIT = 1_000_000
#: a row within this fraction of a step from a grid point goes to that bin (a jitter)
SNAP_FRACTION = 0.25

_NO_WEIGHTS = np.zeros(0)
_NO_WEIGHTS.setflags(write=False)


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
        counts: frames averaged into each drift bin (``n_drift`` of samples.csv), shape
            (N,), or None when unknown (every bin then counts alike).
    """

    t: np.ndarray
    drift: np.ndarray
    temp: np.ndarray
    dt: float
    source: str = "arrays"
    warnings: tuple[str, ...] = field(default_factory=tuple)
    counts: np.ndarray | None = None

    def replace(self, **changes: object) -> Samples:
        """A copy with some fields changed (the rest, counts included, carried over)."""
        return dataclasses.replace(self, **changes)  # type: ignore[arg-type]

    @property
    def noise_weights(self) -> np.ndarray:
        """Measurement-noise weight of each bin: w_k = n̄/n_k (R_k = σ_v²·w_k).

        The mean of n_k frames with independent frame noise of variance σ_f² has
        variance σ_f²/n_k; with σ_v² the variance of a typical bin (n̄ = mean frame count
        of the observed bins), R_k = σ_v² n̄/n_k. A partial first or last bin, dropped
        frames or a slow sensor then weigh what they hold instead of standing out as
        outliers. Empty array when the counts are unknown or all equal (w_k = 1).
        """
        c = self.counts
        if c is None:
            return _NO_WEIGHTS
        obs = np.isfinite(self.drift) & (c > 0)
        if not obs.any() or np.all(c[obs] == c[obs][0]):
            return _NO_WEIGHTS
        nbar = float(np.mean(c[obs]))
        w = np.ones(c.size)
        w[obs] = nbar / c[obs]
        return w

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
        counts: np.ndarray | None = None,
    ) -> Samples:
        """Validate arrays and return samples on a uniform grid.

        ``t`` must be finite and strictly increasing. The grid step ``dt`` defaults to the
        most common step (a record with missing rows or a few early rows keeps its true
        step); each row goes to the nearest grid point ``t_0 + k·dt`` (rows off the grid
        by more than rounding are counted in a warning; two rows in one bin are averaged,
        their counts added), and missing grid points become gaps. NaN drift is a gap; NaN
        temperature is interpolated from its neighbours (a warning says how many).
        ``lines`` (file line of each row) lets errors point into the source file;
        ``counts`` (frames per bin, ``n_drift``) weights each bin's measurement noise.
        """
        t = np.asarray(t, dtype=float)
        drift = np.asarray(drift, dtype=float)
        temp = np.asarray(temp, dtype=float)
        if not (t.shape == drift.shape == temp.shape) or t.ndim != 1:
            raise DataError(f"{source}: t, drift and temp must be 1-D arrays of one length")
        if counts is not None:
            counts = np.asarray(counts, dtype=float)
            if counts.shape != t.shape:
                raise DataError(f"{source}: counts must have the shape of t")

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
            raise DataError(f"{where(bad[0] + 1)}: duplicated time t = {when(t[bad[0] + 1])}")
        bad = np.flatnonzero(steps < 0)
        if bad.size:
            i = bad[0] + 1
            raise DataError(
                f"{where(i)}: time goes backwards (t = {when(t[i])} after {when(t[i - 1])}); "
                "samples must be in increasing time order"
            )
        bad = np.flatnonzero(np.isinf(drift) | np.isinf(temp))
        if bad.size:
            raise DataError(f"{where(bad[0])}: infinite drift or temperature")
        if counts is not None:
            bad = np.flatnonzero(~np.isfinite(counts) | (counts < 0))
            if bad.size:
                raise DataError(f"{where(bad[0])}: frame count {counts[bad[0]]!r} is not a "
                                "count (>= 0)")
        warnings: list[str] = []
        if dt is None:
            dt = common_step(t)
        if not (dt > 0 and math.isfinite(dt)):
            raise DataError(f"{source}: sampling step dt must be positive, got {dt!r}")
        if steps.size:
            rel = t - t[0]  # epoch times lose nothing: the grid is relative to the first row
            k = np.rint(rel / dt)
            n = int(k[-1]) + 1
            if n > max(MAX_GRID_FACTOR * t.size, MIN_GRID_LIMIT):
                j = int(np.argmax(steps))
                raise DataError(
                    f"{where(j + 1)}: time jumps by {steps[j]:.6g} s (from t = {when(t[j])} "
                    f"to {when(t[j + 1])}), {steps[j] / dt:.3g} steps of {dt:g} s: the "
                    f"grid would need {n:,} samples for {t.size:,} rows — a timestamp typo?"
                )
            off = np.abs(rel - k * dt)
            far = np.flatnonzero(off > SNAP_FRACTION * dt)
            if far.size:
                i = far[0]
                raise DataError(
                    f"{where(i)}: t = {when(t[i])} is not on the {dt:g}-s grid started at "
                    f"{when(t[0])} (off by {off[i]:.3g} s, more than {SNAP_FRACTION:g} of a "
                    "step); give the step with --dt or resample the data to a uniform step"
                )
            tol = 1e-6 * dt + 8 * np.spacing(np.abs(t))
            moved = np.flatnonzero(off > tol)
            if moved.size:
                warnings.append(
                    f"{moved.size} rows off the {dt:g}-s grid (up to {off.max():.3g} s, first "
                    f"at {where(moved[0])}) put in the nearest bin"
                )
            idx = k.astype(np.int64)
            if n != t.size or moved.size:
                drift, temp, counts, n_merged = _to_grid(idx, n, drift, temp, counts)
                if n_merged:
                    warnings.append(f"{n_merged} rows shared a bin with another row and "
                                    "were averaged into it")
                missing = n - (t.size - n_merged)
                if missing:
                    warnings.append(
                        f"{missing} missing time steps filled as gaps (no drift measured "
                        "there)"
                    )
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
        if counts is not None:
            counts = np.where(np.isfinite(drift), counts, 0.0)
        for a in (t, drift, temp, counts):
            if a is not None:
                a.setflags(write=False)
        return cls(t=t, drift=drift, temp=temp, dt=float(dt), source=source,
                   warnings=tuple(warnings), counts=counts)

    @classmethod
    def read_csv(cls, path: str | Path, *, dt: float | None = None) -> Samples:
        """Read a CSV with a header containing ``t``, ``drift`` and ``temp`` columns.

        UTF-8 text (a byte-order mark is skipped). An ``n_drift`` column (frames per bin,
        as in a run's samples.csv) weights each bin's measurement noise; other columns are
        ignored. Empty or ``nan`` cells in drift/temp are gaps, and so are missing rows
        (``dt``: the grid step, default the most common step); anything else unparsable
        is an error naming the file and line. A last line without its line end and with
        fewer cells than the header is torn (a writer stopped mid-line, e.g. a daemon
        killed while appending): it is left out, with a warning.
        """
        path = Path(path)
        text = read_text(path)
        torn = bool(text) and not text.endswith(("\n", "\r"))
        reader = csv.reader(io.StringIO(text, newline=""))
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
        wanted = REQUIRED_COLUMNS + (("n_drift",) if "n_drift" in names else ())
        cols = [names.index(c) for c in wanted]
        rows: list[list[float]] = []
        lines: list[int] = []
        try:
            body = list(reader)
        except csv.Error as exc:  # e.g. a cell over csv.field_size_limit() (128 KiB)
            raise DataError(f"{path}: line {reader.line_num}: not CSV ({exc})") from None
        torn = torn and bool(body) and len(body[-1]) < len(names)
        if torn:
            body.pop()
        fast = _columns(body, cols)
        if fast is not None:
            arr = fast
            lines = list(range(2, 2 + len(body)))
            body = []
        for lineno, row in enumerate(body, start=2):
            if not row or all(not c.strip() for c in row):
                continue
            vals = []
            for c, name in zip(cols, wanted, strict=True):
                cell = row[c].strip() if c < len(row) else ""
                if cell == "" or cell.lower() == "nan":
                    if name == "t":
                        raise DataError(f"{path}: line {lineno}: column t is empty")
                    vals.append(0.0 if name == "n_drift" else math.nan)
                    continue
                try:
                    vals.append(float(cell))
                except ValueError:
                    raise DataError(
                        f"{path}: line {lineno}: column {name}: {cell!r} is not a number"
                    ) from None
            rows.append(vals)
            lines.append(lineno)
        if fast is None:
            if not rows:
                raise DataError(f"{path}: no data rows after the header")
            arr = np.array(rows)
        s = cls.from_arrays(arr[:, 0], arr[:, 1], arr[:, 2], dt=dt, source=str(path),
                            lines=np.array(lines),
                            counts=arr[:, 3] if arr.shape[1] > 3 else None)
        if torn:
            note = f"{path}: torn last line (no line end) left out"
            s = s.replace(warnings=(*s.warnings, note))
        return s

    def to_csv(self, path: str | Path) -> None:
        """Write ``t, drift, temp`` (gaps as empty drift cells) to ``path``, and
        ``n_drift`` when the frame counts are known."""
        with Path(path).open("w", newline="") as fh:
            w = csv.writer(fh)
            counts = self.counts
            w.writerow(REQUIRED_COLUMNS + (("n_drift",) if counts is not None else ()))
            for i, (a, b, c) in enumerate(zip(self.t, self.drift, self.temp, strict=True)):
                row = [repr(float(a)), "" if math.isnan(b) else repr(float(b)), repr(float(c))]
                if counts is not None:
                    row.append(f"{counts[i]:g}")
                w.writerow(row)


def _columns(body: list[list[str]], cols: list[int]) -> np.ndarray | None:
    """The wanted columns of CSV rows as floats, each converted whole by numpy (the same
    values as ``float(cell)``), or None when a row is short or blank, or a cell is empty
    or not a number, or ``t`` is NaN: then the row-by-row reader, which names the line."""
    if not body or min(map(len, body)) <= max(cols):
        return None
    try:
        arr = np.column_stack([np.array([r[c] for r in body], dtype=float) for c in cols])
    except ValueError:
        return None
    if np.isnan(arr[:, 0]).any():
        return None
    if arr.shape[1] > 3:  # n_drift: an empty or nan count is 0 frames
        arr[:, 3] = np.where(np.isnan(arr[:, 3]), 0.0, arr[:, 3])
    return arr


#: times above this (s) are Unix epoch times (after 1973): errors print them as UTC too
EPOCH_FROM = 1e8


def when(t: float) -> str:
    """A row's time as an error names it: ``12.5 s``, or for an epoch time every digit
    and the UTC date (``1733300000.25 s (2024-12-04 08:13:20.25 UTC)``, not
    ``1.7e+09 s``)."""
    if not (math.isfinite(t) and t >= EPOCH_FROM):
        return f"{t:g} s"
    utc = _dt.datetime.fromtimestamp(t, _dt.UTC)
    return f"{t:.6f}".rstrip("0").rstrip(".") + \
        f" s ({utc.strftime('%Y-%m-%d %H:%M:%S')}{f'{t % 1:.6f}'[1:].rstrip('0').rstrip('.')} UTC)"


def common_step(t: np.ndarray) -> float:
    """The record's own step (s): the median of the steps near the most common one.

    Missing rows (steps of 2Δt, an outage), a row that came a little early, or a cadence
    that alternates 9, 10 and 11 s leave it at the true step; the smallest step would not.
    Steps are compared at 1e-6 of the median step.
    """
    t = np.asarray(t, dtype=float)
    steps = np.diff(t)
    if steps.size == 0:
        return 1.0
    q = max(float(np.median(steps)) * 1e-6, 1e-9)
    vals, cnt = np.unique(np.rint(steps / q), return_counts=True)
    mode = float(vals[np.argmax(cnt)] * q)
    near = steps[(steps > 0.75 * mode) & (steps < 1.5 * mode)]
    dt = float(np.median(near))
    # timestamps with jitter (a 1-Hz logger at ±0.05 s: steps of 0.9 and 1.1 s, whose
    # median is either): the step whose grid the rows lie on, the least-squares slope of
    # t against the grid index, started from the mean of the steps near the mode
    rel = t - t[0]
    k = np.rint(rel / float(np.mean(near)))
    # — only where the median's grid leaves rows off it and the fitted one does not
    if t.size >= 10 and k[-1] > 0 and np.all(np.diff(k) >= 0) and \
            _off_grid(rel, dt) > SNAP_FRACTION * dt:  # (a slope needs rows)
        fit = float(k @ rel / (k @ k))
        if _off_grid(rel, fit) <= SNAP_FRACTION * fit:
            dt = fit
    # 1.0 s, not 1.000003 s, from jittered rows; but only where the rows lie on the
    # round step's grid as well (a logger clock 0.04 % fast keeps its own step)
    nice = float(f"{dt:.3g}")
    if abs(nice - dt) <= 1e-3 * dt and _off_grid(rel, nice) <= _off_grid(rel, dt) + 1e-3 * dt:
        return nice
    return float(np.rint(dt / q) * q)


def _off_grid(rel: np.ndarray, dt: float) -> float:
    """The largest distance (s) of times ``rel`` from the grid of step ``dt`` through 0."""
    return float(np.max(np.abs(rel - np.rint(rel / dt) * dt)))


def _to_grid(idx: np.ndarray, n: int, drift: np.ndarray, temp: np.ndarray,
             counts: np.ndarray | None):
    """Rows at grid indices ``idx`` onto a grid of ``n`` points: averages per bin (a drift
    mean weighted by its frame counts where known), NaN where no row is."""
    w = counts if counts is not None else np.ones(idx.size)
    ok_d = np.isfinite(drift) & (w > 0)
    sw = np.bincount(idx, weights=np.where(ok_d, w, 0.0), minlength=n)
    sd = np.bincount(idx, weights=np.where(ok_d, w * np.nan_to_num(drift), 0.0), minlength=n)
    ok_t = np.isfinite(temp)
    nt = np.bincount(idx, weights=ok_t.astype(float), minlength=n)
    st = np.bincount(idx, weights=np.where(ok_t, temp, 0.0), minlength=n)
    with np.errstate(invalid="ignore", divide="ignore"):
        d = np.where(sw > 0, sd / np.where(sw > 0, sw, 1.0), np.nan)
        tm = np.where(nt > 0, st / np.where(nt > 0, nt, 1.0), np.nan)
    rows = np.bincount(idx, minlength=n)
    merged = int(np.sum(np.maximum(rows - 1, 0)))
    return d, tm, sw, merged


def read_text(path: Path) -> str:
    """The UTF-8 text of ``path`` (a byte-order mark skipped); a clear error otherwise."""
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise DataError(f"{path}: cannot open: {exc.strerror}") from exc
    if raw.startswith((b"\xff\xfe", b"\xfe\xff")):
        raise DataError(f"{path}: UTF-16 text; save it as UTF-8 (plain text CSV)")
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = raw.count(b"\n", 0, exc.start) + 1
        raise DataError(f"{path}: line {line}: not UTF-8 text (byte 0x{raw[exc.start]:02x}); "
                        "save it as UTF-8") from None
    if "\x00" in text:
        line = text.count("\n", 0, text.index("\x00")) + 1
        raise DataError(f"{path}: line {line}: a NUL character: not a text file")
    return text
