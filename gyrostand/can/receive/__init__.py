"""The receive path: the decoding listener and its parts, one concern each.

- :mod:`~gyrostand.can.receive.listener`: :class:`~gyrostand.can.receive.listener.DecodingListener`,
  the :class:`can.Listener` (constructor, Notifier callbacks, consumer side, stats).
- :mod:`~gyrostand.can.receive.state`: the state the parts share, and frame routing.
- :mod:`~gyrostand.can.receive.timing`: the timing rule (accept, hold, confirm, reject).
- :mod:`~gyrostand.can.receive.frames`: the per-frame path.
- :mod:`~gyrostand.can.receive.arrays`: the array path (the per-frame rules on arrays).
- :mod:`~gyrostand.can.receive.commands`: the command queue.
- :mod:`~gyrostand.can.receive.counts`: the counters, by name, and their snapshot.
- :mod:`~gyrostand.can.receive.extract`: precompiled signal extractors.

Importing this package imports neither python-can nor cantools; its modules do.
"""
