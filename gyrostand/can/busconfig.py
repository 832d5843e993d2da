"""A session's ``can.Bus`` arguments, and where each one came from.

Every key is taken from the first source that has it, most binding first:

1. the command line (``-i/-c/-b/--fd/--data-bitrate``, ``--bus-kwargs KEY=VALUE...``,
   ``--app-name``),
2. the session file's ``bus:`` (which may be empty: ``bus: {}``),
3. python-can's own configuration, in the order :func:`can.util.load_config` reads it:
   ``can.rc``, the environment (``CAN_INTERFACE``, ``CAN_CHANNEL``, ``CAN_BITRATE``,
   ``CAN_CONFIG`` JSON; with ``config_context: X`` first the ``_X``-suffixed ones), then
   the config files of :data:`can.util.CONFIG_FILES` (``~/can.conf``, ``/etc/can.conf``,
   ``~/.can``, ``~/.canrc``; ``can.ini`` on Windows; a later file overrides an earlier
   one; section ``[X]`` before ``[default]``).

Text from the environment and the files is typed as python-can types it
(:func:`can.util.cast_from_string`: ``500000`` an int, ``true`` a bool). The result goes
to ``can.Bus`` as it is, which would have filled the same keys from the same places: what
this module adds is the record of where each came from (``run --check`` prints it) and a
clear error naming the sources when no ``interface`` is found in any of them.
"""

from __future__ import annotations

import os
import socket
from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

import can
import can.util

__all__ = ["COMMAND_LINE", "SESSION_FILE", "ResolvedBus", "resolve_bus",
           "python_can_sources", "parse_bus_kwarg", "socketcan_available"]

COMMAND_LINE = "command line"
SESSION_FILE = "session file"

#: the variables python-can reads for one key each (:func:`can.util.load_environment_config`)
_ENV_KEYS = {"interface": "CAN_INTERFACE", "channel": "CAN_CHANNEL", "bitrate": "CAN_BITRATE"}

#: keys shown first, in this order; the rest follow in the order found
_FIRST = ("interface", "channel", "bitrate")


@dataclass(frozen=True)
class ResolvedBus:
    """The ``can.Bus`` arguments (``values``) and, per key, the source that gave it
    (``sources``: ``"command line"``, ``"session file"``, ``"env CAN_CHANNEL"``,
    ``"python-can config ~/.canrc"``, ...)."""

    values: Mapping[str, Any]
    sources: Mapping[str, str]

    def describe(self) -> list[str]:
        """One line per key: ``interface = 'virtual'  (python-can config ~/.canrc)``."""
        width = max((len(k) for k in self.values), default=0)
        return [f"{k:<{width}} = {v!r}  ({self.sources[k]})" for k, v in self.values.items()]


def python_can_sources(context: str | None = None) -> list[tuple[str, dict[str, Any]]]:
    """python-can's own configuration as ``(label, {key: value})`` pairs, most binding
    first (the order of :func:`can.util.load_config` after the arguments given); values as
    read (text from the environment and the files)."""
    out: list[tuple[str, dict[str, Any]]] = []
    if can.rc:
        out.append(("can.rc", dict(can.rc)))
    contexts = ([context] if context else []) + [None]
    for ctx in contexts:
        suffix = f"_{ctx}" if ctx else ""
        env = can.util.load_environment_config(ctx)
        for key, value in env.items():
            var = _ENV_KEYS.get(key)
            named = var is not None and os.environ.get(var + suffix)
            out.append((f"env {var}{suffix}" if named else f"env CAN_CONFIG{suffix}",
                        {key: value}))
    for ctx in contexts:
        section = ctx or "default"
        for path in reversed(can.util.CONFIG_FILES):  # a later file overrides an earlier
            found = can.util.load_file_config(os.path.expanduser(path), section)
            if found:
                where = path if section == "default" else f"{path} [{section}]"
                out.append((f"python-can config {where}", found))
    return out


def resolve_bus(session: Mapping[str, Any],
                command_line: Mapping[str, Any] | None = None) -> ResolvedBus:
    """The ``can.Bus`` arguments of a session: ``command_line`` over ``session`` (the
    session file's ``bus:``) over :func:`python_can_sources`. The legacy ``bustype`` key
    counts as ``interface``, as python-can reads it."""
    given = [(COMMAND_LINE, dict(command_line or {})), (SESSION_FILE, dict(session))]
    context = next((d["config_context"] for _, d in given if d.get("config_context")), None)
    values: dict[str, Any] = {}
    sources: dict[str, str] = {}
    for label, found in given + python_can_sources(context):
        typed = label not in (COMMAND_LINE, SESSION_FILE)
        if "bustype" in found:
            bustype = found.pop("bustype")
            if not found.get("interface"):
                found["interface"] = bustype
        for key, value in found.items():
            if key in values:
                continue
            values[key] = can.util.cast_from_string(value) \
                if typed and isinstance(value, str) else value
            sources[key] = label
    order = [k for k in _FIRST if k in values] + [k for k in values if k not in _FIRST]
    return ResolvedBus(MappingProxyType({k: values[k] for k in order}),
                       MappingProxyType({k: sources[k] for k in order}))


def parse_bus_kwarg(text: str) -> tuple[str, Any]:
    """``KEY=VALUE`` of ``--bus-kwargs`` as python-can's tools read it: KEY an identifier
    (``-`` read as ``_``), VALUE typed by :func:`can.util.cast_from_string`. Raises
    ValueError naming the argument."""
    key, sep, value = text.partition("=")
    key = key.replace("-", "_")
    if not sep or not key.isidentifier() or any(c.isspace() for c in value):
        raise ValueError(f"expected KEY=VALUE (a python-can bus argument), got {text!r}")
    return key, can.util.cast_from_string(value)



def socketcan_available(channel: str = "can0") -> bool:
    """Whether python-can's ``socketcan`` interface can open ``channel`` here: the system
    has ``socket.AF_CAN``, a raw CAN socket opens (the kernel has SocketCAN), and a
    network interface named ``channel`` exists."""
    if not all(hasattr(socket, n) for n in ("AF_CAN", "CAN_RAW", "if_nametoindex")):
        return False
    try:
        with socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW):
            pass
        socket.if_nametoindex(channel)
    except OSError:
        return False
    return True
