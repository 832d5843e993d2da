"""Opening the bus, and building/sending the daemon's frames by DBC message name.

Every payload is encoded by cantools from signal values; nothing is hand-packed. The frame
layouts are described in ``dbc/README.md``; a user DBC that carries messages with the same
signal names works the same way (the session loader checks the signals exist).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping, Sequence
from typing import Any

import can
from cantools.database.can import Database, Message

from gyrostand.can.dbc import MessageRef, find_message
from gyrostand.core.terms import VOCABULARY, summary_bits
from gyrostand.errors import CanEdgeError

__all__ = [
    "open_bus",
    "FrameEncoder",
    "MODEL_TERM_BITS",
    "IDENTIFIER_CODES",
    "STATE_CODES",
    "STATUS_CODES",
    "ACK_REASONS",
    "COMMANDS",
    "model_terms_mask",
]

log = logging.getLogger(__name__)

#: Bit i of ``ModelTerms`` in GS_SUMMARY = term i (PRODUCT.md's vocabulary order); a plugin
#: term's bit follows the built-ins' (its ``Term.bit``, :func:`model_terms_mask`).
MODEL_TERM_BITS = VOCABULARY
IDENTIFIER_CODES = {"lkf": 0, "lsq": 1, "ml": 2}
STATE_CODES = {"idle": 0, "running": 1, "stopping": 2, "stopped": 3, "fault": 4}
STATUS_CODES = {"ok": 0, "warning": 1, "not_converged": 2, "failed": 3,
                "insufficient_data": 4}
ACK_REASONS = {"ok": 0, "unknown_command": 1, "wrong_state": 2, "busy": 3, "malformed": 4,
               "not_for_me": 5, "rate_limited": 6}
COMMANDS = {1: "start", 2: "stop", 3: "reset", 4: "snapshot"}


def model_terms_mask(terms: Sequence[str], width: int | None = None) -> int:
    """``ModelTerms`` bitmask of a model's term names: bit ``Term.bit`` of each (the
    built-ins in vocabulary order, plugins after them). An unknown term, or one whose bit
    does not fit a signal of ``width`` bits, is a CanEdgeError naming it."""
    bits = summary_bits()
    mask = 0
    for t in terms:
        if t not in bits:
            raise CanEdgeError(f"ModelTerms: unknown model term {t!r}")
        if width is not None and bits[t] >= width:
            raise CanEdgeError(f"ModelTerms: term {t!r} has summary bit {bits[t]}, beyond "
                               f"the {width}-bit ModelTerms signal of the DBC; widen it")
        mask |= 1 << bits[t]
    return mask


def open_bus(bus_cfg: Mapping[str, Any]) -> can.BusABC:
    """``can.Bus(**bus_cfg)``, with failures as :class:`CanEdgeError` naming the bus."""
    where = f"interface={bus_cfg.get('interface')!r} channel={bus_cfg.get('channel')!r}"
    try:
        return can.Bus(**dict(bus_cfg))
    except Exception as exc:  # CanError, ImportError of a driver, OSError, TypeError...
        raise CanEdgeError(f"cannot open CAN bus ({where}): {exc}") from exc


def _width(msg: Message, signal: str) -> int | None:
    """Bit length of ``signal`` in ``msg`` (None when the message lacks it)."""
    return next((int(x.length) for x in msg.signals if x.name == signal), None)


def _wrap(value: int, sig) -> int:
    """Cumulative counts wrap modulo the signal's range (documented in dbc/README.md)."""
    top = int(sig.maximum) if sig.maximum is not None else (1 << sig.length) - 1
    return int(value) % (top + 1)


class FrameEncoder:
    """Encode (and optionally send) frames of ``db`` by message name or :class:`MessageRef`.

    Values are saturated into the DBC range (NaN is kept for float signals); signals not
    given get their DBC initial value or 0; a multiplexed message gets exactly the signals
    its multiplexer values select.
    """

    def __init__(self, db: Database, bus: can.BusABC | None = None) -> None:
        self.db = db
        self.bus = bus

    def _message(self, ref: str | int | MessageRef) -> Message:
        if isinstance(ref, MessageRef):
            return self.db.get_message_by_name(ref.name)
        return find_message(self.db, ref)[1]

    def encode(self, ref: str | int | MessageRef, signals: Mapping[str, float], *,
               timestamp: float = 0.0) -> can.Message:
        """One frame of message ``ref`` carrying ``signals`` (physical values)."""
        msg, data = self.signal_values(ref, signals)
        try:
            payload = msg.encode(data, strict=False)
        except Exception as exc:
            raise CanEdgeError(f"cannot encode {msg.name} from {data}: {exc}") from exc
        return can.Message(arbitration_id=msg.frame_id, is_extended_id=msg.is_extended_frame,
                           data=payload, timestamp=timestamp, is_fd=bool(msg.is_fd),
                           is_rx=False)

    def signal_values(self, ref: str | int | MessageRef,
                      signals: Mapping[str, float]) -> tuple[Message, dict[str, float]]:
        """The cantools message and the complete, saturated signal dict that
        :meth:`encode` would encode (defaults filled, inactive multiplexed signals left out).
        """
        msg = self._message(ref)
        by_name = {s.name: s for s in msg.signals}
        unknown = set(signals) - set(by_name)
        if unknown:
            raise CanEdgeError(f"message {msg.name} has no signal(s) {sorted(unknown)}")
        values: dict[str, float] = {}

        def value(sig) -> float:
            if sig.name in values:
                return values[sig.name]
            v = signals.get(sig.name)
            if v is None:
                v = sig.initial if sig.initial is not None else 0
            v = float(v)
            if not math.isnan(v):
                if sig.minimum is not None:
                    v = max(v, float(sig.minimum))
                if sig.maximum is not None:
                    v = min(v, float(sig.maximum))
            if not sig.is_float:
                if math.isnan(v):
                    raise CanEdgeError(f"{msg.name}.{sig.name}: NaN in an integer signal")
                v = int(round((v - sig.offset) / sig.scale)) * sig.scale + sig.offset
            values[sig.name] = v
            return v

        def active(sig) -> bool:
            if not sig.multiplexer_ids:
                return True
            mux = by_name[sig.multiplexer_signal]
            return active(mux) and int(value(mux)) in sig.multiplexer_ids

        return msg, {s.name: value(s) for s in msg.signals if active(s)}

    def send(self, frames: can.Message | Sequence[can.Message],
             timeout: float | None = 1.0) -> None:
        """Send frames on :attr:`bus`, wrapping failures in :class:`CanEdgeError`."""
        if self.bus is None:
            raise CanEdgeError("FrameEncoder has no bus to send on")
        if isinstance(frames, can.Message):
            frames = [frames]
        for f in frames:
            try:
                self.bus.send(f, timeout=timeout)
            except Exception as exc:
                raise CanEdgeError(f"cannot send frame 0x{f.arbitration_id:X} on "
                                   f"{self.bus.channel_info}: {exc}") from exc

    # -- the daemon's frames -------------------------------------------------------------
    def result_frames(self, ref: str | MessageRef, identifier: str, values: Sequence[float],
                      stds: Sequence[float], counter: int, *,
                      timestamp: float = 0.0) -> list[can.Message]:
        """Two frames per parameter i: Kind 0 with the estimate, Kind 1 with its std."""
        if len(values) != len(stds):
            raise CanEdgeError(f"{len(values)} values but {len(stds)} standard deviations")
        code = IDENTIFIER_CODES[identifier]
        out = []
        for i, (v, s) in enumerate(zip(values, stds, strict=True)):
            common = {"Identifier": code, "Param": i, "NParams": len(values),
                      "Counter": counter % 256}
            out.append(self.encode(ref, {"Kind": 0, "Value": v, **common}, timestamp=timestamp))
            out.append(self.encode(ref, {"Kind": 1, "Std": s, **common}, timestamp=timestamp))
        return out

    def summary_frame(self, ref: str | MessageRef, identifier: str, status: str,
                      model_terms: Sequence[str], samples: int, residual_rms: float, *,
                      timestamp: float = 0.0) -> can.Message:
        """Fit summary; Samples and ResidualRms saturate at the DBC maximum."""
        return self.encode(ref, {
            "Identifier": IDENTIFIER_CODES[identifier], "Status": STATUS_CODES[status],
            "ModelTerms": model_terms_mask(model_terms, _width(self._message(ref),
                                                                "ModelTerms")),
            "Samples": samples,
            "ResidualRms": residual_rms if math.isfinite(residual_rms) else 0.0,
        }, timestamp=timestamp)

    def status_frames(self, ref: str | MessageRef, state: str, counter: int, *, bins: int,
                      gaps: int, decoded: int, rejected: int, bus_errors: int, late: int,
                      outages: int = 0, timestamp: float = 0.0) -> list[can.Message]:
        """The heartbeat: pages 0, 1, 2 with one Counter; counts wrap (see README).
        ``outages`` goes into page 2's ``Outages`` where the DBC has that signal."""
        msg = self._message(ref)
        s = {x.name: x for x in msg.signals}
        c = counter % 16
        pages = (
            {"Page": 0, "State": STATE_CODES[state], "Bins": _wrap(bins, s["Bins"]),
             "Gaps": _wrap(gaps, s["Gaps"])},
            {"Page": 1, "FramesDecoded": _wrap(decoded, s["FramesDecoded"]),
             "FramesRejected": _wrap(rejected, s["FramesRejected"])},
            {"Page": 2, "BusErrors": _wrap(bus_errors, s["BusErrors"]),
             "LateFrames": _wrap(late, s["LateFrames"]),
             **({"Outages": _wrap(outages, s["Outages"])} if "Outages" in s else {})},
        )
        return [self.encode(ref, {"Counter": c, **p}, timestamp=timestamp) for p in pages]

    def ack_frame(self, ref: str | MessageRef, command: int, sequence: int, ok: bool,
                  reason: str = "ok", node: int = 1, *, timestamp: float = 0.0) -> can.Message:
        """Acknowledge (``ok``) or refuse a command, echoing its Command and Sequence."""
        data = {"Command": command, "Sequence": sequence, "Result": 0 if ok else 1,
                "Reason": ACK_REASONS[reason]}
        if "Node" in {x.name for x in self._message(ref).signals}:
            data["Node"] = node
        return self.encode(ref, data, timestamp=timestamp)

    def command_frame(self, ref: str | MessageRef, command: str | int, sequence: int,
                      target: int = 255, *, timestamp: float = 0.0) -> can.Message:
        """A command (for tests and tools that drive a daemon)."""
        code = command if isinstance(command, int) else \
            {v: k for k, v in COMMANDS.items()}[command]
        sigs = {x.name for x in self._message(ref).signals}
        data = {"Command": code, "Sequence": sequence % 256}
        if "Target" in sigs:
            data["Target"] = target
        return self.encode(ref, data, timestamp=timestamp)
