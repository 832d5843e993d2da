"""Helpers of the daemon tests: session configs derived from configs/demo.yaml, a live run
on a fresh virtual channel with the simulated stand and an observer bus, and decoding of
the daemon's response frames with the DBC."""

from __future__ import annotations

import copy
import itertools
import threading
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import can
import yaml

from gyrostand.config import SessionConfig, parse_config
from gyrostand.session.live import run_live
from gyrostand.session.pipeline import RunOutcome
from gyrostand.session.stand import SimulatedStand

ROOT = Path(__file__).resolve().parents[2]
DEMO = ROOT / "configs" / "demo.yaml"
TRUTH = {"markov.beta": 0.0333, "markov.sigma": 0.1, "temp.gamma": -0.001}
_channels = itertools.count()


def demo_dict() -> dict[str, Any]:
    return yaml.safe_load(DEMO.read_text())


def make_cfg(out: Path, *, channel: str | None = None, duration: float | None = None,
             rate: float = 10.0, lkf: dict | None = None, bus: dict | None = None,
             period: float = 10.0, **top: Any) -> SessionConfig:
    """The demo session on its own virtual channel, writing under ``out``; the stand sends
    drift and temperature at ``rate`` Hz each (fewer frames: faster tests)."""
    d = copy.deepcopy(demo_dict())
    d["session"]["output"] = str(out)
    d["bus"] = bus or {"interface": "virtual", "preserve_timestamps": True,
                       "channel": channel or f"gyrostand-session-{next(_channels)}"}
    d["simulate"]["rates"] = {"drift": rate, "temperature": rate}
    if duration is not None:
        d["simulate"]["duration"] = duration
    if lkf is not None:
        d["gyros"][0]["lkf"] = lkf
    d["responses"]["period"] = period
    d.update(top)
    return parse_config(d, source="test-session.yaml", base_dir=DEMO.parent)


def write_cfg_yaml(path: Path, out: Path, bus: dict, **sim: Any) -> Path:
    d = copy.deepcopy(demo_dict())
    d["session"]["output"] = str(out)
    d["bus"] = bus
    d["dbc"] = str((ROOT / "dbc" / "gyrostand.dbc").resolve())
    d["simulate"].update(sim)
    path.write_text(yaml.safe_dump(d))
    return path


def run_virtual(cfg: SessionConfig, frames: Iterable[can.Message], *,
                send_stop: bool = True, **kw: Any
                ) -> tuple[RunOutcome, list[can.Message], SimulatedStand]:
    """Run the daemon (this thread) and the stand (its thread) on the config's virtual
    channel; an observer bus records every frame on the channel. Returns the outcome, the
    observer's frames, and the stand."""
    observer = can.Bus(interface="virtual", channel=cfg.bus["channel"])
    ready, stop = threading.Event(), threading.Event()
    stand = SimulatedStand(cfg, frames, ready, stop, send_stop=send_stop)
    stand.start()
    try:
        outcome = run_live(cfg, on_ready=lambda _d: ready.set(), stop_event=stop,
                           handle_signals=False, **kw)
        stand.join(10)
        seen = []
        while (f := observer.recv(0)) is not None:
            seen.append(f)
    finally:
        observer.shutdown()
    if stand.error is not None:
        raise stand.error
    return outcome, seen, stand


def decode(cfg: SessionConfig, frames: Iterable[can.Message], name: str) -> list[dict]:
    """Decoded signals of every frame of message ``name``, in bus order."""
    msg = cfg.db.get_message_by_name(name)
    return [dict(msg.decode(f.data, decode_choices=False)) for f in frames
            if f.arbitration_id == msg.frame_id and not f.is_extended_id]


def last_results(cfg: SessionConfig, frames: Iterable[can.Message], message: str
                 ) -> dict[int, dict[int, tuple[float, float]]]:
    """identifier code -> param index -> (value, std), the last value seen of each."""
    out: dict[int, dict[int, list[float]]] = {}
    for d in decode(cfg, frames, message):
        slot = out.setdefault(int(d["Identifier"]), {}).setdefault(int(d["Param"]),
                                                                   [float("nan")] * 2)
        if d["Kind"] == 0:
            slot[0] = d["Value"]
        else:
            slot[1] = d["Std"]
    return {i: {p: (v[0], v[1]) for p, v in ps.items()} for i, ps in out.items()}
