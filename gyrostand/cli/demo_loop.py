"""The demo's loop (``gyrostand demo``): the mission on the virtual bus, end to end.

The simulated stand's gyro has one physical effect more than the session's model holds
(:data:`HIDDEN`, named only at the end, as the truth). The loop is what a test-stand
engineer does with a run:

1. the daemon's run on the session's model (the stand simulator on the virtual bus);
2. ``gyrostand diagnose RUN``: NOT ADEQUATE, the missing effect ranked first, where the
   model fails (the open-loop error above its floor);
3. ``gyrostand fit RUN --add TERM``: the effect added, the error before and after, a
   ledger step;
4. ``gyrostand diagnose RUN`` again: the verdict on the new model;
5. ``gyrostand adopt RUN``: the model written into the session file (here its text is
   edited and validated by adopt's own functions, the diff printed, the file left as it
   is), and the daemon's next run (a new stand record) on it, with its online LKF
   estimating the added effect bin by bin;
6. the report of the first run, its ledger figure showing the error fall.

Each step is the command's own code (the workbench's steps and renderers), printed as the
command prints it.
"""

from __future__ import annotations

import dataclasses
import shlex
import threading
import time
from pathlib import Path
from types import MappingProxyType
from typing import Any, TextIO

from ..config import SessionConfig, SimulateConfig
from ..errors import ConfigError
from .common import fault_status

#: the demo's hidden effect: a quadratic temperature response of the drift
#: (``temp2``, γ₂ in drift units per s·degC²: see ``docs/terms.md``), one an engineer meets
#: as a sensitivity that changes with temperature
HIDDEN: tuple[str, dict[str, float]] = ("temp2", {"temp2.gamma2": -2e-4})


def simulate_section(cfg: SessionConfig) -> SimulateConfig:
    """``cfg``'s ``simulate:`` section; a :class:`ConfigError` naming it when the file has
    none (the demo needs the simulator)."""
    if cfg.simulate is None:
        raise ConfigError(f"{cfg.path}: simulate: missing (the demo needs the simulator)")
    return cfg.simulate


def with_hidden_effect(cfg: SessionConfig, term: str, params: dict[str, float]
                       ) -> SessionConfig:
    """``cfg`` whose simulated gyros have ``term`` (with ``params``) in their truth, the
    session's models unchanged."""
    sim = simulate_section(cfg)
    gyros = {name: dataclasses.replace(
        g, model=g.model if term in g.model else (*g.model, term),
        params=MappingProxyType({**g.params, **params})) for name, g in sim.gyros.items()}
    return dataclasses.replace(cfg, simulate=dataclasses.replace(
        sim, gyros=MappingProxyType(gyros)))


def adopted_through_file(cfg: SessionConfig, models: dict[str, tuple[str, ...]],
                         stream: TextIO) -> SessionConfig:
    """``cfg`` as ``gyrostand adopt`` leaves it: the session file's text edited by adopt's
    own functions (:func:`gyrostand.cli.adopt.plan`, :func:`gyrostand.config.edit.edit_models`;
    the diff printed) and validated from that text, its gyros taken; the file itself is
    not written (the demo's session file stays as it is). The stand's next record: the
    simulator's next seed."""
    import difflib

    from ..config import parse_text
    from ..config.edit import edit_models
    from .adopt import plan

    path = Path(cfg.path)
    text = path.read_text(encoding="utf-8")
    new_models, new_ids, notes = plan(text, models, str(path))
    edited = edit_models(text, new_models, new_ids, str(path))
    diff = difflib.unified_diff(text.splitlines(keepends=True),
                                edited.splitlines(keepends=True), fromfile=str(path),
                                tofile=f"{path} (adopted; the demo does not write it)")
    print("".join(diff) + "".join(f"note: {n}\n" for n in notes), file=stream, flush=True)
    edited_cfg = parse_text(edited, path)  # as adopt validates the file it wrote
    return dataclasses.replace(cfg, gyros=edited_cfg.gyros, simulate=dataclasses.replace(
        simulate_section(cfg), seed=simulate_section(cfg).seed + 1))


def daemon_run(cfg: SessionConfig, out: str | None, stream: TextIO, label: str) -> Any:
    """One run of the daemon against the simulated stand; returns its outcome."""
    from ..session.live import run_live
    from ..session.offline import simulated_frames, truth_params
    from ..session.stand import SimulatedStand

    sim = simulate_section(cfg)
    ready, stop = threading.Event(), threading.Event()
    stand = SimulatedStand(cfg, simulated_frames(cfg), ready, stop)
    stand.start()
    t0 = time.monotonic()
    outcome = run_live(cfg, out=out, on_ready=lambda _d: ready.set(), stop_event=stop,
                       truths=truth_params(cfg))
    wall = time.monotonic() - t0
    stand.join(5)
    if stand.error is not None:
        raise stand.error
    ack = stand.ack
    print(f"{label}: the stand sent {stand.sent} frames; the daemon ran {wall:.1f} s wall "
          f"for {sim.duration or sim.temperature[-1][0]:g} s of frame time; stop "
          + ("acknowledged" if ack and ack.get("Result") == 0 else "not acknowledged"),
          file=stream, flush=True)
    return outcome


def step_header(n: int, text: str, command: str, stream: TextIO) -> None:
    print(f"\n=== {n}. {text}\n    $ {command}\n", file=stream, flush=True)


def loop(cfg: SessionConfig, out: str | None, stream: TextIO) -> int:
    """The loop on every gyro of ``cfg`` (the demo session has one); 0 when it ends
    ADEQUATE with the effect found, else 1."""
    from ..cli.common import print_outcome
    from ..report import write_report
    from ..report.views import DiagnosisView, FitStepView
    from ..session.offline import truth_params
    from ..workbench import open_subject, run_diagnose, run_fit
    from ..workbench.advice import adopt_command
    from .common import emit, invocation

    prog = invocation()
    term, params = HIDDEN
    hidden = with_hidden_effect(cfg, term, params)
    models = ", ".join(f"{g.name}: {','.join(g.model)}" for g in cfg.gyros)
    print(f"demo: the stand's gyro has one physical effect more than the session's model "
          f"({models}); the workbench finds it (the truth is named at the end)",
          file=stream, flush=True)
    step_header(1, "the daemon's run on the session's model",
                f"{prog} run {shlex.quote(str(cfg.path))}", stream)
    first = daemon_run(hidden, out, stream, "run 1")
    print_outcome(first, stream, truth_params(cfg))
    if not first.ok:
        return fault_status(first)
    run_dir = first.run_dir
    found: dict[str, tuple[str, ...]] = {}
    ok = True
    for g in cfg.gyros:
        subject = open_subject(run_dir, gyro=g.name)
        step_header(2, f"where the model fails ({g.name})", f"{prog} diagnose {run_dir}",
                    stream)
        before = run_diagnose(subject)
        fit = f"{prog} fit {run_dir}"
        emit(DiagnosisView(before, f"{subject.samples.source} (gyro {g.name})",
                           subject.ledger_path, fit_command=fit), "text", stream)
        if before.adequate or not before.significant:
            print(f"{g.name}: the model is adequate: no effect to add", file=stream)
            ok = False
            continue
        add = before.significant[0].term
        step_header(3, f"add what is missing: {add}", f"{fit} --add {add}", stream)
        step = run_fit(subject, [add])
        emit(FitStepView(step, subject.ledger_path), "text", stream)
        subject = open_subject(run_dir, gyro=g.name)
        step_header(4, "the verdict on the new model", f"{prog} diagnose {run_dir}", stream)
        after = run_diagnose(subject)
        emit(DiagnosisView(after, f"{subject.samples.source} (gyro {g.name})",
                           subject.ledger_path, fit_command=fit,
                           adopt_command=adopt_command(subject) if after.adequate else None),
             "text", stream)
        found[g.name] = subject.model.names
        ok = ok and after.adequate and add == term
        err0, err1 = step.before_error, step.after_error
        if err0 is not None and err1 is not None:
            print(f"{g.name}: open-loop model error {err0.rms:.3g} -> {err1.rms:.3g} "
                  f"{subject.unit} ({100 * (1 - err1.rms / err0.rms):.0f} % less) with "
                  f"{add}", file=stream)
    step_header(5, "the adopted model on the daemon's next run (its online LKF included)",
                f"{prog} adopt {shlex.quote(str(run_dir))}   "
                f"# then: {prog} run {shlex.quote(str(cfg.path))}", stream)
    nxt = adopted_through_file(hidden, found, stream)
    second = daemon_run(nxt, out, stream, "run 2")
    print_outcome(second, stream, truth_params(hidden))
    step_header(6, "the report: model vs measurements, the ledger", f"{prog} report {run_dir}",
                stream)
    for g in cfg.gyros:
        page = write_report(open_subject(run_dir, gyro=g.name))
        print(f"html report ({g.name}, the loop's ledger): {page}", file=stream)
    if second.ok:
        for f in second.finals:
            page = write_report(open_subject(second.run_dir, gyro=f.gyro))
            print(f"html report ({f.gyro}, the adopted model's run): {page}", file=stream)
    truth = ", ".join(f"{k} = {v:g}" for k, v in params.items())
    print(f"\nthe truth: the stand's gyro had {term} ({truth}) beside the session's model; "
          + ("the loop found it, and the model with it is ADEQUATE" if ok else
             "the loop did not end where it should (see above)"), file=stream)
    return 0 if ok and second.ok else 1
