"""Session layer (layer 3): the daemon and its drivers.

- :mod:`~gyrostand.session.pipeline`: the daemon's core (bins → online identification →
  files and response frames; commands; heartbeat), blind to where frames come from.
- :mod:`~gyrostand.session.live`: ``gyrostand run``: bus, Notifier, worker loop, signals.
- :mod:`~gyrostand.session.offline`: ``gyrostand replay``; the simulator's truth and frames.
- :mod:`~gyrostand.session.online`: per-gyro online LKF/LSQ.
- :mod:`~gyrostand.session.final`: final batch fits, ``result.json``, ``report.txt``.
- :mod:`~gyrostand.session.outputs`: the run folder, ``run.log``, ``estimates.csv``.
"""
