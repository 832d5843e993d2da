"""The session-file parser's primitives: each reads one value at a key path and fails
with a :class:`~gyrostand.errors.ConfigError` naming the file and the path. The sections
(:mod:`.gyros`, :mod:`.simulate`, :mod:`.parser`) build on them."""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from gyrostand.can.codes import check_width, role_codes
from gyrostand.can.dbc import MessageRef, find_message
from gyrostand.errors import CanEdgeError, ConfigError

from .schema import (
    MODEL_TERMS,
    clip,
    key_path,
    kind_of,
)

#: a number YAML 1.1 leaves a string (``1e0``, ``5E-3``: an exponent without a dot)
_NUMBER = re.compile(r"[-+]?(\d+\.?\d*|\.\d+)[eE][-+]?\d+")


class Reader:
    """What every section of the parser reads with, and the state they share: the
    file's name, its folder, the DBC once loaded, ``sampling.dt``, the known terms and
    the default channel ``match``."""

    def __init__(self, source: str, base_dir: Path) -> None:
        self.source = source
        self.base = base_dir
        self.db: Any = None
        self.dbc_name = "DBC"
        self.dt = 1.0  # sampling.dt once parsed (bounds of rates given in 1/s)
        self.terms: tuple[str, ...] = MODEL_TERMS  # + plugin terms once loaded
        self.match = "id"  # the session's default channel `match` once parsed
        self.drift_unit = "deg/h"  # session.drift_unit once parsed

    # -- helpers ---------------------------------------------------------------------
    def fail(self, path: str, msg: str) -> ConfigError:
        return ConfigError(f"{self.source}: {clip(path, 200)}: {clip(msg, 600)}")

    def mapping(self, value: Any, path: str, required: tuple[str, ...],
                optional: tuple[str, ...]) -> dict[str, Any]:
        if not isinstance(value, Mapping):
            raise self.fail(path, f"expected a mapping, got {kind_of(value)}")
        unknown = [k for k in value if k not in required and k not in optional]
        if unknown:
            allowed = ", ".join(required + optional)
            raise self.fail(key_path(path, str(unknown[0])),
                            f"unknown key (allowed here: {allowed})")
        for k in required:
            if k not in value:
                raise self.fail(key_path(path, k), "missing required key")
        return dict(value)

    def number(self, value: Any, path: str, *, lo: float | None = None,
               hi: float | None = None, lo_open: bool = False) -> float:
        if isinstance(value, str) and _NUMBER.fullmatch(value.strip()):
            value = float(value)  # YAML 1.1 reads 1e0 (an exponent, no dot) as a string
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.fail(path, f"expected a number, got {kind_of(value)}")
        try:
            x = float(value)
        except OverflowError:
            raise self.fail(path, f"too large ({len(str(abs(value)))}-digit integer)") from None
        if not math.isfinite(x):
            raise self.fail(path, f"must be finite, got {value!r}")
        if lo is not None and (x < lo or (lo_open and x == lo)):
            raise self.fail(path, f"must be {'>' if lo_open else '>='} {lo:g}, got {value!r}")
        if hi is not None and x > hi:
            raise self.fail(path, f"must be <= {hi:g}, got {value!r}")
        return x

    def integer(self, value: Any, path: str, lo: int | None = None,
                hi: int | None = None) -> int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.fail(path, f"expected an integer, got {kind_of(value)}")
        if (lo is not None and value < lo) or (hi is not None and value > hi):
            raise self.fail(path, f"must be in [{lo}, {hi}], got {value}")
        return value

    def string(self, value: Any, path: str) -> str:
        if not isinstance(value, str) or not value:
            raise self.fail(path, f"expected a non-empty string, got {kind_of(value)}")
        return value

    def names(self, value: Any, path: str, vocabulary: tuple[str, ...]) -> tuple[str, ...]:
        if isinstance(value, str):
            value = [v.strip() for v in value.split(",")]
        if not isinstance(value, list) or not value:
            raise self.fail(path, f"expected a non-empty list, got {kind_of(value)}")
        out: list[str] = []
        for i, v in enumerate(value):
            if v not in vocabulary:
                raise self.fail(f"{path}[{i}]", f"{v!r} is not one of: {', '.join(vocabulary)}")
            if v in out:
                raise self.fail(f"{path}[{i}]", f"{v!r} is listed twice")
            out.append(v)
        return tuple(out)

    def message(self, value: Any, path: str) -> MessageRef:
        ref, extended = value, None
        if isinstance(value, Mapping):
            m = self.mapping(value, path, ("message",), ("extended",))
            ref, extended = m["message"], self.boolean(m.get("extended"), f"{path}.extended")
            path = f"{path}.message"
        try:
            return find_message(self.db, ref, extended, source=self.dbc_name)[0]
        except CanEdgeError as exc:
            raise self.fail(path, str(exc)) from None

    def boolean(self, value: Any, path: str) -> bool | None:
        if value is None or isinstance(value, bool):
            return value
        raise self.fail(path, f"expected true or false, got {kind_of(value)}")

    def require_signals(self, ref: MessageRef, path: str, needed: tuple[str, ...],
                        role: str | None = None) -> None:
        """``ref`` must carry the signals ``needed``; for a message of the daemon's in
        ``role`` (``result``, ``summary``, ``status``, ``ack``, ``command``) also the value
        tables of its codes (:func:`gyrostand.can.codes.role_codes`)."""
        msg = self.db.get_message_by_name(ref.name)
        have = {s.name for s in msg.signals}
        missing = [s for s in needed if s not in have]
        if missing:
            raise self.fail(path, f"message {ref.name} lacks signal(s) {', '.join(missing)} "
                                  f"needed here (see dbc/README.md)")
        if role is not None:
            try:
                role_codes(msg, role, self.dbc_name)
            except CanEdgeError as exc:
                raise self.fail(path, str(exc)) from None

    def require_width(self, ref: MessageRef, path: str, model: tuple[str, ...]) -> None:
        """The summary's ``ModelTerms`` must have a bit for every term of ``model``."""
        from gyrostand.can.bus import model_terms_mask

        try:
            check_width(self.db.get_message_by_name(ref.name), "ModelTerms",
                        model_terms_mask(model), f"the model {', '.join(model)}",
                        self.dbc_name)
        except CanEdgeError as exc:
            raise self.fail(path, str(exc)) from None

    # -- sections --------------------------------------------------------------------

    def model_of(self, model: tuple[str, ...], path: str) -> Any:
        """The core :class:`~gyrostand.core.model.Model` of ``model`` (a ConfigError at
        ``path`` when the terms do not make one, so no run folder is started for it)."""
        from gyrostand.core.model import Model
        from gyrostand.errors import ModelError

        try:
            return Model.parse(list(model))
        except ModelError as exc:
            raise self.fail(path, str(exc)) from None
