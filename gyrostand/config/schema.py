"""The session file's frozen objects and the constants the parser checks against."""

from __future__ import annotations

import logging
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from gyrostand.can.dbc import MessageRef, SignalRef
from gyrostand.can.framesim import FrameSimOptions
from gyrostand.can.units import Conversion
from gyrostand.core import registry
from gyrostand.core.names import VOCABULARY
from gyrostand.core.options import LkfOptions

log = logging.getLogger(__name__)

#: The model-term vocabulary of PRODUCT.md (the contract shared by config, CLI, JSON).
MODEL_TERMS = VOCABULARY
#: every identifier a gyro's ``identifiers:`` may name (the registry's)
IDENTIFIERS = registry.names()

#: Signals the daemon writes or reads in its own response/command messages.
RESULT_SIGNALS = ("Kind", "Identifier", "Param", "Value", "Std", "NParams", "Counter")
SUMMARY_SIGNALS = ("Identifier", "Status", "ModelTerms", "Samples", "ResidualRms")
STATUS_SIGNALS = ("Page", "Counter", "State", "Bins", "Gaps", "FramesDecoded",
                  "FramesRejected", "BusErrors", "LateFrames")
COMMAND_SIGNALS = ("Command", "Sequence")
ACK_SIGNALS = ("Command", "Sequence", "Result", "Reason")

#: a session's and a gyro's name: a letter or digit, then letters, digits, ``_.-``
NAME_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")
#: a parameter's name ``<term>.<param>``: groups (term, param)
PARAM_RE = re.compile(r"^([a-z_0-9]+)\.([A-Za-z_][A-Za-z_0-9]*)$")
MIN_RATE_HZ, MAX_RATE_HZ = 10.0, 1000.0
#: bounds of sampling.dt (s): frames at up to 1000 Hz in bins of at least 10 ms, at most 1 h
MIN_DT, MAX_DT = 0.01, 3600.0
#: sampling.max_gap / dt at most: the gap bins one forward jump may emit
MAX_GAP_BINS = 1_000_000
#: |sampling.epoch| and simulate.start at most (s; ~ year 5138): beyond, doubles of frame
#: time are coarser than 1e-5 s
MAX_EPOCH = 1e11
#: how frames are matched to a mapped message: full id, or J1939 PGN (see ChannelConfig)
MATCHES = ("id", "pgn")


@dataclass(frozen=True)
class ChannelConfig:
    """One measured channel: the DBC signal carrying it and, optionally, its rolling counter."""

    signal: SignalRef
    counter: SignalRef | None = None
    #: "id": frames match on the full id; "pgn": J1939, on the PGN whatever the priority
    #: and source address (extended ids only)
    match: str = "id"
    #: the decoded value into the channel's unit (°C, the session's drift unit); None: the
    #: DBC's unit already is it (the samples are the decoded values, to the bit)
    convert: Conversion | None = None
    #: a validity/status signal of the same message: (signal name, raw values, accept):
    #: a frame whose value is in the set is dropped (accept False) or kept (accept True)
    valid: tuple[str, frozenset[float], bool] | None = None
    #: J1939 source address this channel's device sends from (``match: pgn``); None: any
    source_address: int | None = None
    #: the unit of the channel's samples: the DBC's, or the one it is converted to
    unit: str = ""


@dataclass(frozen=True)
class ResultConfig:
    """Messages the daemon sends a gyro's results in (see ``dbc/README.md``)."""

    values: MessageRef
    summary: MessageRef | None = None


#: The online LKF of a gyro (its ``lkf:`` section): the lkf identifier's typed options
#: (:class:`~gyrostand.core.options.LkfOptions`; a value left out is estimated from a
#: warm-up of ``warmup`` bins).
LkfConfig = LkfOptions


@dataclass(frozen=True)
class GyroConfig:
    name: str
    drift: ChannelConfig
    temperature: ChannelConfig
    model: tuple[str, ...]
    identifiers: tuple[str, ...]
    result: ResultConfig | None = None
    lkf: LkfConfig = field(default_factory=LkfConfig)

    def options(self, identifier: str) -> Any:
        """The typed options of ``identifier`` for this gyro: its section of the session
        file where it has one (``lkf:``), else the identifier's defaults."""
        ident = registry.get(identifier)
        section = getattr(self, ident.name, None)
        return section if isinstance(section, ident.Options) else ident.Options()


@dataclass(frozen=True)
class SamplingConfig:
    """Binning: ``dt`` bin width (s); ``epoch`` bin grid origin (s, None: the first frame's
    timestamp floored to a multiple of dt); ``buffer`` capacity of the decoded-sample buffer
    (samples); ``max_gap`` largest forward jump of frame time accepted (s)."""

    dt: float = 1.0
    epoch: float | None = None
    buffer: int = 65536
    max_gap: float = 3600.0


@dataclass(frozen=True)
class ResponsesConfig:
    """Frames the daemon sends and the command channel it listens to. ``period`` (s) between
    result rounds and ``heartbeat`` (s) between status frames, in frame time; ``node`` is
    this daemon's id in the command's ``Target`` (255 addresses every daemon)."""

    period: float = 10.0
    heartbeat: float = 1.0
    status: MessageRef | None = None
    ack: MessageRef | None = None
    command: MessageRef | None = None
    node: int = 1
    command_rate: float = 10.0


@dataclass(frozen=True)
class ReconnectConfig:
    """What the daemon does when the bus goes away (e.g. a ``remote`` server stops):
    retry opening it, waiting ``first_delay`` s, then twice as long each time up to
    ``max_delay`` s; after ``max_time`` s without a bus it stops in state ``fault``
    (0: at once). ``at_start``: s to keep trying, with the same backoff, when the bus
    cannot be opened at startup (an adapter not plugged in yet, a server not up yet;
    default 0: fail at once); a bus that can never open (unknown interface, a driver
    that is not installed, bad arguments) fails at once anyway."""

    max_time: float = 600.0
    first_delay: float = 0.25
    max_delay: float = 10.0
    at_start: float = 0.0


@dataclass(frozen=True)
class SimGyroConfig:
    """True model of a simulated gyro: terms and ``<term>.<param>`` values."""

    model: tuple[str, ...]
    params: Mapping[str, float]


@dataclass(frozen=True, kw_only=True)
class SimulateConfig(FrameSimOptions):
    """Stand simulator: the frame simulator's options (its fields, owned by
    :class:`~gyrostand.can.framesim.FrameSimOptions`: frame rates (Hz), uniform timestamp
    jitter half-width (s), drop probability, sensor quantization steps (physical units,
    0 = only the DBC's resolution), ``start`` absolute timestamp of t = 0 (s since the Unix
    epoch: BLF stores absolute time), ``seed``, also of the truth) and the truth: the
    temperature breakpoints ``(t s, T degC)``, linear between, each gyro's true model,
    the ``duration`` (s; default the last breakpoint's time), ``realtime`` pacing."""

    temperature: tuple[tuple[float, float], ...]
    gyros: Mapping[str, SimGyroConfig]
    duration: float | None = None
    realtime: bool = False


@dataclass(frozen=True)
class SessionConfig:
    """A validated session. ``db`` is the loaded cantools database (not compared)."""

    path: Path
    name: str
    output: Path
    bus: Mapping[str, Any]
    dbc_path: Path
    sampling: SamplingConfig
    gyros: tuple[GyroConfig, ...]
    responses: ResponsesConfig
    simulate: SimulateConfig | None = None
    db: Any = field(default=None, repr=False, compare=False)
    reconnect: ReconnectConfig = field(default_factory=ReconnectConfig)
    #: live runs: each once-a-second acknowledgement is fdatasync'ed (raw log first,
    #: then samples and estimates), so it survives a power cut, not only a crash
    fsync: bool = True
    #: formats written beside the CSVs at the run's end (``session.formats``; of
    #: :data:`gyrostand.runfolder.layout.DATA_FORMATS`)
    formats: tuple[str, ...] = ()
    #: the unit every drift is binned in (``session.drift_unit``); DBC signals in another
    #: angular-rate unit are converted at decode time (:mod:`gyrostand.can.units`)
    drift_unit: str = "deg/h"
    #: where each key of ``bus`` came from (``session file``, ``command line``, ``env
    #: CAN_CHANNEL``, ``python-can config ~/.canrc``; :mod:`gyrostand.can.busconfig`);
    #: empty until the command line resolves the bus (then: every key of ``bus``)
    bus_sources: Mapping[str, str] = field(default_factory=dict, compare=False)

    def gyro(self, name: str) -> GyroConfig:
        for g in self.gyros:
            if g.name == name:
                return g
        raise KeyError(name)


def key_path(path: str, key: str) -> str:
    """The key path of ``key`` inside ``path`` (``"<top>"``: the file's top level), as
    error messages name it: ``sampling.dt``."""
    return key if path == "<top>" else f"{path}.{key}"


def kind_of(value: Any) -> str:
    """What ``value`` is, as an error message says it was given: ``nothing``, a mapping
    or list by its type, anything else by its type and (clipped) value."""
    if value is None:
        return "nothing"
    return f"{type(value).__name__} {clip(repr(value), 80)}" if not isinstance(
        value, (dict, list)) else type(value).__name__


def clip(text: str, n: int) -> str:
    """``text`` cut to ``n`` characters (an error message quotes input, never all of it)."""
    return text if len(text) <= n else f"{text[:n]}... ({len(text)} characters)"

