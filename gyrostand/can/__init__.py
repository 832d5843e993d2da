"""The CAN edge (layer 2): the only part of gyrostand that imports python-can / cantools.

- :mod:`~gyrostand.can.dbc`: load a DBC, resolve messages/signals by name or frame id.
- :mod:`~gyrostand.can.routes`: the channel map and the route (decoder) of one frame id.
- :mod:`~gyrostand.can.receive`: the Notifier listener (decode, check, time, count,
  append), frame by frame or on arrays.
- :mod:`~gyrostand.can.logs`: recorded logs read in this process or a reader process.
- :mod:`~gyrostand.can.binning`: Δt bins from frame timestamps; ``samples.csv`` writer.
- :mod:`~gyrostand.can.ingest`: listener FIFO -> binner, shared by live and replay.
- :mod:`~gyrostand.can.recorder` / :mod:`~gyrostand.can.replay`: raw logs in and out.
- :mod:`~gyrostand.can.bus`: open the bus; encode/send result, status, ack frames.
- :mod:`~gyrostand.can.framesim`: frames from a 1-s truth, for any DBC layout.

Importing this package imports neither python-can nor cantools; its modules do.
"""
