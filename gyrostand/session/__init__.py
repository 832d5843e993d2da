"""Session layer (layer 3): the daemon and its drivers.

- :mod:`~gyrostand.session.pipeline`: the daemon's core (bins → online identification →
  files and response frames; commands; heartbeat), blind to where frames come from.
  Its parts: :mod:`~gyrostand.session.acked` (acknowledged writing of samples and
  estimates), :mod:`~gyrostand.session.responses` (response scheduling and the frame
  sinks), :mod:`~gyrostand.session.commands` (the command protocol's state machine),
  :mod:`~gyrostand.session.runend` (the end of a run).
- :mod:`~gyrostand.session.live`: ``gyrostand run``: the worker loop, outages, and the
  release of every resource; :mod:`~gyrostand.session.buslink`: the bus, its Notifier,
  the backoff of (re)opening it, signals as a stop request.
- :mod:`~gyrostand.session.offline`: ``gyrostand replay``; the simulator's truth and frames.
- :mod:`~gyrostand.session.online`: per-gyro online LKF/LSQ.
- :mod:`~gyrostand.session.final`: final batch fits, ``result.json``, ``report.txt``.
- the run folder, ``run.log``, ``estimates.csv``: :mod:`gyrostand.runfolder`.
"""
