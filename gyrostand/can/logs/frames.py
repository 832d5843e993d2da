"""A received frame as the decoding listener sees it: the :data:`Frame` tuple, its key
and flag bits, and :func:`frame_fields` taking them from a :class:`can.Message`.

Shared by the log readers (:mod:`~gyrostand.can.logs.read`, the reader process
:mod:`~gyrostand.can.logs.reader`, the BLF array parser
:mod:`~gyrostand.can.logs.blfarray`) and the receive path
(:mod:`gyrostand.can.receive`). Imports nothing at run time (python-can only for types).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import can

__all__ = ["Frame", "frame_fields", "EXTENDED_KEY_BIT", "ERROR_FRAME", "REMOTE_FRAME"]

#: bit set in a frame key for an extended (29-bit) id, so standard 0x100 and extended 0x100
#: are different keys of one int-keyed dict (:func:`~gyrostand.can.dbc.frame_key`)
EXTENDED_KEY_BIT = 1 << 29
ERROR_FRAME, REMOTE_FRAME = 1, 2

#: a received frame as the listener uses it: ``(timestamp s, key, flags, payload)``; key
#: the id (| EXTENDED_KEY_BIT for an extended id), flags ERROR_FRAME | REMOTE_FRAME
Frame = tuple[float, int, int, "bytes | bytearray"]


def frame_fields(msg: can.Message) -> Frame:
    """The fields of ``msg`` the decoding listener looks at, as a :data:`Frame`."""
    aid = msg.arbitration_id
    return (msg.timestamp, aid | EXTENDED_KEY_BIT if msg.is_extended_id else aid,
            (ERROR_FRAME if msg.is_error_frame else 0)
            | (REMOTE_FRAME if msg.is_remote_frame else 0), msg.data)
