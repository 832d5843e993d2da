"""Recorded CAN logs: reading them in this process or a reader process beside it.

- :mod:`~gyrostand.can.logs.frames`: the :data:`~gyrostand.can.logs.frames.Frame` tuple
  the listener receives, and :func:`~gyrostand.can.logs.frames.frame_fields`.
- :mod:`~gyrostand.can.logs.read`: :func:`~gyrostand.can.logs.read.read_log` and
  friends, every format python-can reads, damage skipped and counted
  (:class:`~gyrostand.can.logs.read.LogDamage`).
- :mod:`~gyrostand.can.logs.textlog`: ASC, candump and CSV logs read line by line, a
  damaged line skipped and counted.
- :mod:`~gyrostand.can.logs.blfarray`: BLF containers parsed as arrays
  (:class:`~gyrostand.can.logs.blfarray.FrameArrays`).
- :mod:`~gyrostand.can.logs.reader`: the reader process
  (:class:`~gyrostand.can.logs.reader.ReaderProcess`,
  ``python -m gyrostand.can.logs.reader``).

Importing this package imports nothing; its modules do (the reader process starts with
python-can alone).
"""
