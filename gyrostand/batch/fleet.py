"""The fleet view: which runs are outliers, how much a parameter moves from turn-on to
turn-on and from unit to unit, how it ages; one HTML page with the plots and the table.

Outliers — the robust z-score of Iglewicz & Hoaglin, per parameter within a gyro type
(the manifest's ``type`` column, else ``gyro_type``, else the whole fleet):

    z_i = 0.6745 (x_i − median x) / MAD,    MAD = median |x_i − median x|

flagged when |z_i| > 3.5 (at least ``MIN_GROUP`` runs in the group, MAD > 0). The median
and MAD ignore the outliers themselves, so one bad run cannot hide another as a mean and
std would.

Spreads — with a ``serial`` column, per parameter and type, from the runs of units with
at least two runs (one-way analysis of variance, serial = group):

    turn-on to turn-on  s_w = sqrt( Σ_u Σ_i (x_ui − x̄_u)² / Σ_u (n_u − 1) )
    unit to unit        s_b = sqrt( max(0, var(x̄_u) − s_w² · mean(1/n_u)) )

each with a 95 % χ² interval (:func:`spreads`).

Trend (ageing) — with ``serial`` and ``date`` (ISO dates), per unit with two or more
dates: the least-squares slope of the parameter over time, per year, with its t interval
from three runs on; ``--trend SERIAL`` picks one unit for its own section and plot.
"""

from __future__ import annotations

import base64
import datetime as _dt
import html
import io
import json
import math
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from ..runfolder import write_atomic
from .table import columns

__all__ = ["param_columns", "robust_z", "outliers", "with_outliers", "spreads", "trends",
           "write_view",
           "Z_LIMIT", "MIN_GROUP", "CONFIDENCE"]

#: |robust z| above this is an outlier (Iglewicz & Hoaglin's 3.5)
Z_LIMIT = 3.5
#: fewest runs of a type for outlier flags
MIN_GROUP = 5
_TYPE_KEYS = ("type", "gyro_type")


def param_columns(rows: Sequence[dict[str, Any]]) -> list[str]:
    """The parameter columns (each has its ``_std`` beside it), sorted."""
    keys: set[str] = set()
    for r in rows:
        keys.update(r)
    return sorted(k for k in keys if f"{k}_std" in keys and "." in k)


def _type_of(row: dict[str, Any]) -> str:
    for k in _TYPE_KEYS:
        if row.get(k):
            return str(row[k])
    return "all"


def _num(x: Any) -> float | None:
    if isinstance(x, bool) or not isinstance(x, int | float):
        return None
    return float(x) if math.isfinite(x) else None


def _median(xs: Sequence[float]) -> float:
    s = sorted(xs)
    n = len(s)
    return s[n // 2] if n % 2 else 0.5 * (s[n // 2 - 1] + s[n // 2])


def robust_z(values: Sequence[float]) -> list[float] | None:
    """Each value's robust z-score, or None when there are too few or MAD is 0."""
    if len(values) < MIN_GROUP:
        return None
    med = _median(values)
    mad = _median([abs(v - med) for v in values])
    if not mad > 0:
        return None
    return [0.6745 * (v - med) / mad for v in values]


def _scores(rows: Sequence[dict[str, Any]]
            ) -> list[tuple[dict[str, Any], str, float, str, float]]:
    """(row, parameter, value, gyro type, robust z) of every ok row's parameter whose
    type has a group large enough to judge."""
    out = []
    ok = [r for r in rows if r.get("status") == "ok"]
    for p in param_columns(ok):
        groups: dict[str, list[tuple[dict[str, Any], float]]] = {}
        for r in ok:
            v = _num(r.get(p))
            if v is not None:
                groups.setdefault(_type_of(r), []).append((r, v))
        for typ, members in groups.items():
            zs = robust_z([v for _, v in members])
            for (r, v), z in zip(members, zs or (), strict=False):
                out.append((r, p, v, typ, z))
    return out


def outliers(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """One entry per (row, parameter) flagged: run, gyro, type, parameter, value, z."""
    return _flags(_scores(rows))


def _flags(scores: list[tuple[dict[str, Any], str, float, str, float]]
           ) -> list[dict[str, Any]]:
    return [{"run": r["run"], "gyro": r.get("gyro"), "type": typ, "parameter": p,
             "value": v, "z": z} for r, p, v, typ, z in scores if abs(z) > Z_LIMIT]


def with_outliers(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """``rows`` with the outlier flags in the table itself, where people filter (fleet.csv,
    fleet.parquet): ``outliers`` (``parameter z=…`` of each flagged parameter, ``; ``
    between) and ``max_abs_z`` (the largest |robust z| of the row's parameters; empty where
    no group is large enough to judge). The flags are :func:`outliers`'s."""
    scores = _scores(rows)
    flags: dict[tuple[Any, Any], list[dict[str, Any]]] = {}
    for f in _flags(scores):
        flags.setdefault((f["run"], f["gyro"]), []).append(f)
    zmax: dict[tuple[Any, Any], float] = {}
    for r, _, _, _, z in scores:
        key = (r["run"], r.get("gyro"))
        zmax[key] = max(zmax.get(key, 0.0), abs(z))
    out = []
    for r in rows:
        key = (r["run"], r.get("gyro"))
        extra: dict[str, Any] = {}
        if key in zmax:
            extra["max_abs_z"] = round(zmax[key], 3)
            extra["outliers"] = "; ".join(f"{f['parameter']} z={f['z']:.2f}"
                                          for f in flags.get(key, ()))
        out.append({**r, **extra})
    return out


#: the confidence level of every interval of the fleet view
CONFIDENCE = 0.95


def _chi2_std_ci(s: float, dof: int) -> list[float]:
    """The χ² interval of a standard deviation ``s`` on ``dof`` degrees of freedom."""
    from scipy.stats import chi2

    a = (1 - CONFIDENCE) / 2
    return [s * math.sqrt(dof / chi2.ppf(1 - a, dof)), s * math.sqrt(dof / chi2.ppf(a, dof))]


def spreads(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per type and parameter: units, runs, turn-on-to-turn-on s_w and unit-to-unit s_b,
    each with its :data:`CONFIDENCE` interval.

    s_w is pooled over the units with two or more runs (χ² interval on Σ(n_u − 1) dof).
    The units' means scatter by s_b² + s_w²/n_u, so s_b is the std of the means with the
    turn-on part taken out (the one-way random-effects estimate):

        s_b² = max(0, var(x̄_u) − s_w² · mean(1/n_u))

    and its interval is the χ² interval of var(x̄_u) (units − 1 dof) with the same part
    taken out of both ends (clamped at 0). ``unit_means_std`` is std(x̄_u) itself."""
    out = []
    ok = [r for r in rows if r.get("status") == "ok" and r.get("serial")]
    for p in param_columns(ok):
        groups: dict[str, dict[str, list[float]]] = {}
        for r in ok:
            v = _num(r.get(p))
            if v is not None:
                groups.setdefault(_type_of(r), {}).setdefault(_unit(r), []).append(v)
        for typ, units in groups.items():
            ss, dof = 0.0, 0
            for xs in units.values():
                if len(xs) > 1:
                    m = sum(xs) / len(xs)
                    ss += sum((x - m) ** 2 for x in xs)
                    dof += len(xs) - 1
            s_w = math.sqrt(ss / dof) if dof else None
            means = [sum(xs) / len(xs) for xs in units.values()]
            s_m = s_b = None
            s_b_ci = None
            if len(means) > 1:
                mm = sum(means) / len(means)
                s_m = math.sqrt(sum((m - mm) ** 2 for m in means) / (len(means) - 1))
                part = (s_w or 0.0) ** 2 * sum(1 / len(x) for x in units.values()) / len(units)
                s_b = math.sqrt(max(0.0, s_m * s_m - part))
                lo, hi = _chi2_std_ci(s_m, len(means) - 1)
                s_b_ci = [math.sqrt(max(0.0, lo * lo - part)), math.sqrt(max(0.0, hi * hi - part))]
            out.append({"type": typ, "parameter": p, "units": len(units),
                        "runs": sum(len(x) for x in units.values()),
                        "turn_on_to_turn_on": s_w,
                        "turn_on_to_turn_on_ci": _chi2_std_ci(s_w, dof) if dof and s_w else None,
                        "unit_to_unit": s_b, "unit_to_unit_ci": s_b_ci,
                        "unit_means_std": s_m})
    return out


def _date(x: Any) -> _dt.date | None:
    try:
        return _dt.date.fromisoformat(str(x)[:10])
    except ValueError:
        return None


def _unit(row: dict[str, Any]) -> str:
    return f"{row['serial']}/{row.get('gyro')}"


def _of_unit(row: dict[str, Any], unit: str) -> bool:
    """Whether ``row`` belongs to ``unit``: ``SERIAL`` (each of its gyros) or
    ``SERIAL/GYRO``."""
    return unit in (str(row["serial"]), _unit(row))


def trends(rows: Sequence[dict[str, Any]], unit: str | None = None) -> list[dict[str, Any]]:
    """Per unit (serial/gyro) and parameter with two or more dates: the least-squares
    slope per year; with three or more runs also its standard error and
    :data:`CONFIDENCE` interval (Student t on n − 2 dof). ``unit``: only that unit
    (``SERIAL`` for each of its gyros, or ``SERIAL/GYRO``)."""
    from scipy.stats import t as student

    out = []
    ok = [r for r in rows if r.get("status") == "ok" and r.get("serial") and
          _date(r.get("date")) is not None]
    if unit is not None:
        ok = [r for r in ok if _of_unit(r, unit)]
    for p in param_columns(ok):
        units: dict[str, list[tuple[float, float]]] = {}
        for r in ok:
            v = _num(r.get(p))
            d = _date(r.get("date"))
            if v is not None and d is not None:
                units.setdefault(_unit(r), []).append((d.toordinal() / 365.25, v))
        for name, pts in sorted(units.items()):
            ts = [t for t, _ in pts]
            if len(set(ts)) < 2:
                continue
            tm = sum(ts) / len(ts)
            vm = sum(v for _, v in pts) / len(pts)
            sxx = sum((t - tm) ** 2 for t in ts)
            slope = sum((t - tm) * (v - vm) for t, v in pts) / sxx
            rec: dict[str, Any] = {"unit": name, "parameter": p, "runs": len(pts),
                                   "slope_per_year": slope, "mean": vm,
                                   "slope_std": None, "slope_ci": None}
            dof = len(pts) - 2
            if dof > 0:
                rss = sum((v - vm - slope * (t - tm)) ** 2 for t, v in pts)
                se = math.sqrt(rss / dof / sxx)
                q = float(student.ppf(0.5 + CONFIDENCE / 2, dof))
                rec["slope_std"] = se
                rec["slope_ci"] = [slope - q * se, slope + q * se]
            out.append(rec)
    return out


# --- the page ---------------------------------------------------------------------------

def _png(fig: Any) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90, bbox_inches="tight")
    return base64.b64encode(buf.getvalue()).decode("ascii")


def _plots(rows: Sequence[dict[str, Any]], flags: list[dict[str, Any]]) -> list[tuple[str, str]]:
    """(title, base64 PNG): per parameter, its values by run (outliers marked), and its
    values over dates per unit where there are dates."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ok = [r for r in rows if r.get("status") == "ok"]
    flagged = {(f["run"], f["gyro"], f["parameter"]) for f in flags}
    out = []
    for p in param_columns(ok):
        pts = [(i, r) for i, r in enumerate(ok) if _num(r.get(p)) is not None]
        if not pts:
            continue
        fig, ax = plt.subplots(figsize=(7, 2.6))
        xs = [i for i, _ in pts]
        ys = [float(r[p]) for _, r in pts]
        es = [_num(r.get(f"{p}_std")) or 0.0 for _, r in pts]
        ax.errorbar(xs, ys, yerr=es, fmt="o", ms=3, lw=0.8, color="tab:blue")
        bad = [(i, float(r[p])) for i, r in pts if (r["run"], r.get("gyro"), p) in flagged]
        if bad:
            ax.plot([b[0] for b in bad], [b[1] for b in bad], "o", ms=8, mfc="none",
                    color="tab:red", label=f"|robust z| > {Z_LIMIT:g}")
            ax.legend(fontsize=7)
        ax.set_title(f"{p} by run (±1 std)", fontsize=9)
        ax.set_xlabel("run (table order)", fontsize=8)
        ax.tick_params(labelsize=7)
        out.append((f"{p} by run", _png(fig)))
        plt.close(fig)
        dated: dict[str, list[tuple[_dt.date, float]]] = {}
        for _, r in pts:
            d = _date(r.get("date"))
            if r.get("serial") and d is not None:
                dated.setdefault(_unit(r), []).append((d, float(r[p])))
        if any(len({d for d, _ in v}) > 1 for v in dated.values()):
            fig, ax = plt.subplots(figsize=(7, 2.6))
            for unit, v in sorted(dated.items()):
                v.sort()
                ax.plot([d for d, _ in v], [y for _, y in v], "o-", ms=3, lw=0.8, label=unit)  # type: ignore[arg-type]
            ax.set_title(f"{p} over dates, per unit (ageing)", fontsize=9)
            ax.tick_params(labelsize=7)
            if len(dated) <= 12:
                ax.legend(fontsize=6, ncol=3)
            fig.autofmt_xdate()
            out.append((f"{p} over dates", _png(fig)))
            plt.close(fig)
    return out


_JS = """
document.querySelectorAll('table.sortable th').forEach(function (th, col) {
  th.addEventListener('click', function () {
    var body = th.closest('table').tBodies[0];
    var asc = th.dataset.asc !== '1'; th.dataset.asc = asc ? '1' : '0';
    var rows = Array.from(body.rows);
    rows.sort(function (a, b) {
      var x = a.cells[col].dataset.v ?? a.cells[col].textContent;
      var y = b.cells[col].dataset.v ?? b.cells[col].textContent;
      var nx = parseFloat(x), ny = parseFloat(y);
      var c = (!isNaN(nx) && !isNaN(ny)) ? nx - ny : x.localeCompare(y);
      return asc ? c : -c;
    });
    rows.forEach(function (r) { body.appendChild(r); });
  });
});
"""

_CSS = ("body{font-family:sans-serif;font-size:13px;margin:1em}"
        "table{border-collapse:collapse;margin:0.5em 0}"
        "td,th{border:1px solid #ccc;padding:2px 5px;white-space:nowrap}"
        "th{background:#eee;cursor:pointer}tr.failed td{background:#fdd}"
        "td.flag{background:#fc9}")


def _cell(v: Any) -> str:
    if v is None:
        return "<td></td>"
    if isinstance(v, list) and all(isinstance(x, float) for x in v):
        return "<td>[" + ", ".join(f"{x:.4g}" for x in v) + "]</td>"
    if isinstance(v, float):
        return f'<td data-v="{v!r}">{v:.5g}</td>'
    return f"<td>{html.escape(str(v))}</td>"


def _simple_table(items: Sequence[dict[str, Any]]) -> str:
    if not items:
        return "<p>none</p>"
    cols = list(items[0])
    head = "".join(f"<th>{html.escape(c)}</th>" for c in cols)
    body = "".join("<tr>" + "".join(_cell(it.get(c)) for c in cols) + "</tr>" for it in items)
    return f'<table class="sortable"><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>'


def _unit_plots(rows: Sequence[dict[str, Any]], unit: str,
                trd: Sequence[dict[str, Any]]) -> list[tuple[str, str]]:
    """(title, base64 PNG) per parameter of one unit: its values (±1 std) over dates and
    the fitted ageing line."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    mine = [r for r in rows if r.get("status") == "ok" and r.get("serial")
            and _of_unit(r, unit) and _date(r.get("date")) is not None]
    out = []
    for t in trd:
        p = t["parameter"]
        pts: list[tuple[_dt.date, float, float]] = sorted(
            (day, float(r[p]), _num(r.get(f"{p}_std")) or 0.0)
            for r in mine if _unit(r) == t["unit"] and _num(r.get(p)) is not None
            and (day := _date(r.get("date"))) is not None)
        fig, ax = plt.subplots(figsize=(7, 2.6))
        ax.errorbar([d for d, _, _ in pts], [v for _, v, _ in pts],  # type: ignore[arg-type]
                    yerr=[e for _, _, e in pts], fmt="o", ms=3, lw=0.8)
        tm = sum(d.toordinal() for d, _, _ in pts) / len(pts) / 365.25
        line = [t["mean"] + t["slope_per_year"] * (d.toordinal() / 365.25 - tm)
                for d, _, _ in pts]
        ci = t["slope_ci"]
        lab = f"{t['slope_per_year']:.4g}/year" + (f" [{ci[0]:.3g}, {ci[1]:.3g}]" if ci else "")
        ax.plot([d for d, _, _ in pts], line, "-", lw=1.0, color="tab:red", label=lab)  # type: ignore[arg-type]
        ax.legend(fontsize=7)
        ax.set_title(f"{t['unit']}: {p} over dates (±1 std) and its trend", fontsize=9)
        ax.tick_params(labelsize=7)
        fig.autofmt_xdate()
        out.append((f"{t['unit']} {p} trend", _png(fig)))
        plt.close(fig)
    return out


def write_view(rows: Sequence[dict[str, Any]], out: str | Path,
               attrs: Sequence[str] = (), trend_unit: str | None = None) -> Path:
    """``<out>/fleet.html`` (atomically) and ``<out>/fleet.json`` (flags, spreads,
    trends, and with ``trend_unit`` that unit's trends); the table's runs link to their
    reports."""
    out = Path(out)
    flags = outliers(rows)
    spr = spreads(rows)
    trd = trends(rows)
    mine = trends(rows, trend_unit) if trend_unit else []
    flagged = {(f["run"], f["gyro"], f["parameter"]) for f in flags}
    cols = [c for c in columns(rows, attrs) if c not in ("source", "config", "run_dir")]
    head = "".join(f"<th>{html.escape(c)}</th>" for c in cols)
    body = []
    for r in rows:
        cells = []
        for c in cols:
            v = r.get(c)
            if c == "report" and v:
                rel = os.path.relpath(str(v), out)
                cells.append(f'<td><a href="{html.escape(rel)}">report</a></td>')
            elif (r["run"], r.get("gyro"), c) in flagged:
                cells.append(_cell(v).replace("<td", '<td class="flag"', 1))
            else:
                cells.append(_cell(v))
        cls = ' class="failed"' if r.get("status") != "ok" else ""
        body.append(f"<tr{cls}>" + "".join(cells) + "</tr>")
    n_bad = sum(1 for r in rows if r.get("status") != "ok")
    plots = "".join(f'<figure><img alt="{html.escape(t)}" src="data:image/png;base64,{b}">'
                    f"</figure>" for t, b in _plots(rows, flags))
    page = (
        f"<!doctype html><html><head><meta charset='utf-8'><title>gyrostand fleet</title>"
        f"<style>{_CSS}</style></head><body>"
        f"<h1>Fleet: {len(rows)} run x gyro rows ({n_bad} not ok)</h1>"
        f"<h2>Outliers (|robust z| &gt; {Z_LIMIT:g}, per parameter within a gyro type, "
        f"groups of {MIN_GROUP}+)</h2>{_simple_table(flags)}"
        f"<h2>Spread per parameter (turn-on to turn-on, unit to unit)</h2>"
        f"{_simple_table(spr)}"
        + (f"<h2>Trend of {html.escape(trend_unit)} (slope per year, "
           f"{CONFIDENCE:.0%} interval)</h2>{_simple_table(mine)}"
           + "".join(f'<figure><img alt="{html.escape(t)}" src="data:image/png;base64,{b}">'
                     f"</figure>" for t, b in _unit_plots(rows, trend_unit, mine))
           if trend_unit else "")
        + f"<h2>Trend per unit (slope per year, {CONFIDENCE:.0%} interval)</h2>"
        f"{_simple_table(trd)}"
        f"<h2>Plots</h2>{plots or '<p>no parameters</p>'}"
        f"<h2>Table (click a header to sort)</h2>"
        f'<table class="sortable"><thead><tr>{head}</tr></thead><tbody>{"".join(body)}'
        f"</tbody></table><script>{_JS}</script></body></html>\n")
    write_atomic(out / "fleet.json", json.dumps(
        {"outliers": flags, "spreads": spr, "trends": trd,
         **({"trend_unit": {"unit": trend_unit, "trends": mine}} if trend_unit else {})},
        indent=1, allow_nan=False) + "\n")
    path = out / "fleet.html"
    write_atomic(path, page)
    return path
