"""The receive path's counters: what the listener counts, by name.

:class:`Counts` and :class:`Rejections` are the running counters the
:class:`~gyrostand.can.receive.listener.DecodingListener` increments per frame (slotted dataclasses:
an increment costs what a list item's does); :class:`DecodeStats` is their snapshot, whose
fields (and ``rejected``'s keys, :data:`REASONS`, in that order) are the JSON keys of
``stats.decoder`` in ``result.json`` and ``segments.json``.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

__all__ = ["Counts", "Rejections", "DecodeStats", "REASONS", "COUNT_FIELDS"]


@dataclass(slots=True)
class Rejections:
    """The listener's running count of rejected frames, one field per reason (the
    reasons' names and order: :data:`REASONS`, the keys of :attr:`DecodeStats.rejected`).
    """

    unknown_id: int = 0     # id not in the DBC
    wrong_dlc: int = 0      # payload length differs from the DBC's message length
    undecodable: int = 0    # cantools could not decode (e.g. undefined multiplexer value)
    out_of_range: int = 0   # a mapped value outside the DBC [min|max], or not finite
    bad_timestamp: int = 0  # timestamp not finite
    non_monotonic: int = 0  # timestamp earlier than the previous frame with this id
    time_jump: int = 0      # timestamp more than max_gap after the previous frame
    error_frame: int = 0
    remote_frame: int = 0
    overflow: int = 0       # the sample buffer was full
    not_available: int = 0  # every mapped value a VAL_ code (NotAvailable, Error, SNA...)
    invalid: int = 0        # the message's validity signal marked the frame invalid
    second_source: int = 0  # a mapped J1939 PGN from a 2nd source address (not mapped)
    command_overflow: int = 0  # the command queue was full (a command frame dropped)


#: Rejection reasons, in the order of :attr:`DecodeStats.rejected`.
REASONS = tuple(f.name for f in fields(Rejections))


@dataclass(slots=True)
class Counts:
    """The listener's running counters other than rejections (slots: an increment on the
    receive path costs what a list item's does); :class:`DecodeStats` is their snapshot."""

    received: int = 0  # = decoded + ignored + rejected + held
    decoded: int = 0
    ignored: int = 0  # frames of the DBC that carry no mapped signal
    samples: int = 0
    commands: int = 0
    counter_jumps: int = 0
    bus_errors: int = 0
    listener_errors: int = 0
    not_available: int = 0  # mapped values dropped as VAL_ codes (in any frame)
    other_source: int = 0  # ignored: a mapped PGN from a source address no channel maps


#: The fields of :class:`Counts`, in order (the first keys of ``stats.decoder``).
COUNT_FIELDS = tuple(f.name for f in fields(Counts))


@dataclass(frozen=True)
class DecodeStats:
    """Snapshot of the listener's counters (cumulative since start or reset)."""

    received: int  # = decoded + ignored + rejected_total + held
    decoded: int
    ignored: int
    samples: int
    commands: int
    counter_jumps: int
    bus_errors: int
    listener_errors: int
    rejected: dict[str, int]
    not_available: int = 0  # mapped values dropped as VAL_ codes (in any frame)
    other_source: int = 0  # ignored: a mapped PGN from a source address no channel maps
    clock_steps: int = 0  # confirmed steps of the frames' clock (each re-anchored)
    held: int = 0  # frames waiting for a second frame to confirm their time

    @property
    def rejected_total(self) -> int:
        return sum(self.rejected.values())
