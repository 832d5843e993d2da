"""The command protocol: ``GS_COMMAND`` frames in, a state and acknowledgements out.

An explicit state machine over the run's states (the names the heartbeat's ``State``
carries, :data:`gyrostand.can.bus.STATE_CODES`)::

    idle ──start──▶ running ──stop──▶ stopping ──(end of run)──▶ stopped | fault
      └──────────────stop──────────────▲

:data:`TRANSITIONS` is the whole table for commands: a command that has no entry for the
current state is refused ``wrong_state``; ``reset`` and ``snapshot`` keep the state and
run their action (given by the daemon: restart the online identifiers, write
``snapshot.json``) before the acknowledgement. :data:`END_OF_RUN` is the table the end of
the run follows (:meth:`CommandProtocol.end`). Online identification runs in the
:data:`IDENTIFYING` states.

Before the table is consulted (first match wins): ``Target`` other than this node or 255:
ignored (no answer); over ``responses.command_rate`` commands per second of frame time
(a :class:`TokenBucket` holding ``max(1, rate)``): refused ``rate_limited``, and those
refusals are themselves limited to the same rate (beyond it they are only counted,
``nacks_suppressed``); a frame the listener marked malformed or without
Command/Sequence: refused ``malformed`` (echoing what can be read); a code the command
message does not name (:attr:`CommandProtocol.command_name`): refused
``unknown_command``. Every outcome is counted in :attr:`CommandProtocol.counts` (the keys
of ``stats()["commands"]``).

The protocol does no I/O: :meth:`CommandProtocol.handle` returns the :class:`Ack` to send
(or None); the daemon sends it.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass

from ..can.bus import COMMANDS
from ..can.receive.commands import MALFORMED
from ..can.receive.counts import REASONS

__all__ = ["CommandProtocol", "Ack", "TokenBucket", "TRANSITIONS", "END_OF_RUN",
           "IDENTIFYING", "STATES", "IDLE", "RUNNING", "STOPPING", "STOPPED", "FAULT"]

log = logging.getLogger(__name__)

#: the run's states (names of :data:`gyrostand.can.bus.STATE_CODES`)
IDLE, RUNNING, STOPPING, STOPPED, FAULT = "idle", "running", "stopping", "stopped", "fault"
STATES = (IDLE, RUNNING, STOPPING, STOPPED, FAULT)
#: states in which closed bins update the online identifiers
IDENTIFYING = frozenset({RUNNING, STOPPING})

#: acknowledgement reasons (names of :data:`gyrostand.can.bus.ACK_REASONS`)
OK, UNKNOWN_COMMAND, WRONG_STATE = "ok", "unknown_command", "wrong_state"
MALFORMED_COMMAND, RATE_LIMITED = "malformed", "rate_limited"

#: (state, command name) → next state; anything else is refused ``wrong_state``
TRANSITIONS: Mapping[tuple[str, str], str] = {
    (IDLE, "start"): RUNNING,
    (IDLE, "stop"): STOPPING,
    (RUNNING, "stop"): STOPPING,
    **{(s, c): s for s in (IDLE, RUNNING, STOPPING) for c in ("reset", "snapshot")},
}
#: (state, end-of-run event) → next state: ``end`` begins the end of the run (final fits
#: and files), ``fail`` marks a fault (at any point), ``done`` completes a clean end
END_OF_RUN: Mapping[tuple[str, str], str] = {
    **{(s, "end"): STOPPING for s in (IDLE, RUNNING, STOPPING)},
    **{(s, "fail"): FAULT for s in (IDLE, RUNNING, STOPPING, FAULT)},
    (STOPPING, "done"): STOPPED,
}

#: the counters of :attr:`CommandProtocol.counts`, in their JSON order
COUNTS = ("received", "acked", "nacked", "ignored", "malformed", "unknown", "rate_limited",
          "nacks_suppressed")


class TokenBucket:
    """At most ``rate`` events per second of frame time, bursts up to ``max(1, rate)``."""

    def __init__(self, rate: float) -> None:
        self.rate = float(rate)
        self.capacity = max(1.0, self.rate)
        self.tokens = self.capacity
        self.t = -math.inf

    def take(self, t: float) -> bool:
        """A timestamp earlier than the last one (a command frame of a clock that stepped
        back, or after a stray future one) refills nothing and becomes the reference, so
        one wild timestamp cannot block later commands."""
        if math.isfinite(t):
            if self.t > -math.inf and t > self.t:
                self.tokens = min(self.capacity, self.tokens + (t - self.t) * self.rate)
            self.t = t
        if self.tokens >= 1.0:
            self.tokens -= 1.0
            return True
        return False


@dataclass(frozen=True)
class Ack:
    """An acknowledgement to send: the command's code and sequence echoed, ``ok`` or a
    refusal ``reason`` (a name of :data:`gyrostand.can.bus.ACK_REASONS`)."""

    command: int
    sequence: int
    ok: bool
    reason: str = OK


class CommandProtocol:
    """The state machine of one run (see the module doc).

    Args:
        node: this daemon's id (``responses.node``).
        rate: commands per second of frame time (``responses.command_rate``).
        start_idle: begin ``idle`` instead of ``running``.
        actions: command name → ``action(t)`` run before a successful acknowledgement
            (``reset``, ``snapshot``); an action that raises leaves no acknowledgement.
        command_name: the name of a decoded ``Command`` code, None for a code the
            protocol does not know (default: :data:`gyrostand.can.bus.COMMANDS`).
    """

    def __init__(self, node: int, rate: float, *, start_idle: bool = False,
                 actions: Mapping[str, Callable[[float], object]] | None = None,
                 command_name: Callable[[int], str | None] | None = None) -> None:
        self.node, self.rate = int(node), float(rate)
        self.command_name = command_name if command_name is not None else COMMANDS.get
        self.actions = dict(actions or {})
        self.state = IDLE if start_idle else RUNNING
        self.stop_requested: str | None = None
        self.counts: dict[str, int] = dict.fromkeys(COUNTS, 0)
        self._commands = TokenBucket(rate)
        self._nacks = TokenBucket(rate)

    @property
    def identifying(self) -> bool:
        """Whether closed bins update the online identifiers now."""
        return self.state in IDENTIFYING

    def end(self, event: str) -> str:
        """Follow :data:`END_OF_RUN` on ``event`` (``end``, ``fail``, ``done``); returns
        the new state. Raises ValueError for a step the table does not have."""
        nxt = END_OF_RUN.get((self.state, event))
        if nxt is None:
            raise ValueError(f"no end-of-run step {event!r} from state {self.state!r}")
        self.state = nxt
        return nxt

    def handle(self, t: float, values: dict[str, float]) -> Ack | None:
        """One command frame received at frame time ``t`` (s) with its decoded signals:
        change state, run the action, and return the acknowledgement to send (None: no
        answer). Exceptions of an action propagate (nothing is acknowledged)."""
        self.counts["received"] += 1
        ack = self._decide(t, values)
        if ack is not None:
            self.counts["acked" if ack.ok else "nacked"] += 1
        return ack

    def _decide(self, t: float, values: dict[str, float]) -> Ack | None:
        n = self.counts
        target = values.get("Target")
        if target is not None and int(target) not in (255, self.node):
            n["ignored"] += 1
            log.info("command for node %d ignored (this is node %d)", int(target), self.node)
            return None
        code, seq = values.get("Command"), values.get("Sequence")
        c, q = int(code or 0), int(seq or 0)
        if not self._commands.take(t):
            n["rate_limited"] += 1
            if n["rate_limited"] % 100 == 1:
                log.warning("commands over responses.command_rate = %g/s: %d refused so far",
                            self.rate, n["rate_limited"])
            if self._nacks.take(t):
                return Ack(c, q, False, RATE_LIMITED)
            n["nacks_suppressed"] += 1
            return None
        if MALFORMED in values or code is None or seq is None:
            n["malformed"] += 1
            why = REASONS[int(values[MALFORMED])] if MALFORMED in values else \
                "no Command/Sequence"
            log.warning("malformed command at t=%.3f (%s): %s", t, why,
                        {k: v for k, v in values.items() if k != MALFORMED})
            return Ack(c, q, False, MALFORMED_COMMAND)
        name = self.command_name(c)
        log.info("command %s (seq %d) at t=%.3f", name or c, q, t)
        if name is None:
            n["unknown"] += 1
            return Ack(c, q, False, UNKNOWN_COMMAND)
        nxt = TRANSITIONS.get((self.state, name))
        if nxt is None:
            return Ack(c, q, False, WRONG_STATE)
        action = self.actions.get(name)
        if action is not None:
            action(t)
        if name == "stop":
            self.stop_requested = "stop command"
        self.state = nxt
        return Ack(c, q, True)
