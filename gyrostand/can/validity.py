"""What a DBC says is no measurement: value-table codes and validity signals.

A raw value named in a signal's ``VAL_`` table as not available, an error, invalid, SNA
(``0xFFFF "NotAvailable"``, ``0xFE00 "Error"``) is a code, not a value: the receive path
counts it and never bins it. A *validity signal* is a signal of the same message whose
name says status / valid / qualifier and whose value table names such a state
(``Rate_Status 2 "invalid"``): a frame carrying that state has no valid measurement.

Codes are compared as decoded values (the DBC scaling applied to the raw value, what the
receive path's decoder gives), so the check is one set lookup per mapped value.
"""

from __future__ import annotations

import re
from collections.abc import Iterable

__all__ = ["is_code_name", "code_values", "status_signals", "STATUS_WORDS"]

#: words of a value-table entry that names no measurement
_BAD_WORDS = {"sna", "na", "error", "err", "invalid", "fault", "faulty", "undefined",
              "unavailable", "notavailable", "nodata", "invalidity", "failure", "failed",
              "notvalid", "unknown"}
#: word pairs that do (``not available``, ``no data``, ``not valid``)
_BAD_PAIRS = {("not", "available"), ("no", "data"), ("not", "valid"), ("n", "a"),
              ("not", "ok"), ("no", "signal")}
#: words of a validity/status signal's name
STATUS_WORDS = ("status", "stat", "valid", "validity", "qualifier", "qual", "quality", "vld")


def _words(name: str) -> list[str]:
    parts = re.findall(r"[A-Z]+(?![a-z])|[A-Z]?[a-z]+|\d+", str(name))
    return [p.lower() for p in parts]


def is_code_name(name: str) -> bool:
    """True when a value-table entry's name says the value is no measurement.

    >>> [is_code_name(n) for n in ("NotAvailable", "Error", "SNA", "invalid", "n/a",
    ...                            "valid", "degraded", "ok", "Signal_Not_Valid")]
    [True, True, True, True, True, False, False, False, True]
    """
    w = _words(name)
    if any(x in _BAD_WORDS for x in w):
        return True
    return any(p in _BAD_PAIRS for p in zip(w, w[1:], strict=False))


def code_values(signal) -> frozenset:
    """The decoded values of ``signal`` (a cantools signal) that its value table names as
    no measurement (empty without a table)."""
    choices = getattr(signal, "choices", None) or {}
    conv = signal.conversion
    out = set()
    for raw, name in choices.items():
        if is_code_name(str(name)):
            try:
                out.add(conv.raw_to_scaled(int(raw), False))
            except Exception:  # a table entry the conversion refuses: not a code here
                continue
    return frozenset(out)


def status_signals(message, mapped: Iterable[str]) -> list[tuple[str, frozenset]]:
    """The validity signals of a cantools ``message`` other than ``mapped``: a name with
    a status word whose value table names a state of no measurement, with the decoded
    values of those states."""
    skip = set(mapped)
    out = []
    for sig in message.signals:
        if sig.name in skip or not any(w in STATUS_WORDS for w in _words(sig.name)):
            continue
        bad = code_values(sig)
        if bad:
            out.append((sig.name, bad))
    return out
