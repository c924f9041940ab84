"""Message framing of ULog and DataFlash files, walked before the third-party parser reads
them: how much of the file is whole messages, and where it is not.

pyulog stops quietly when it cannot find the next message (a truncated or misframed log
comes back as the first seconds of the flight), and pymavlink skips bad bytes with a
printed remark; neither tells its caller how much was lost. The walk here does:

* **ULog** (``ULog\\x01\\x12\\x35`` + version + u64 start time = 16 bytes, then messages
  ``u16 size, u8 type, payload``): the chain of headers from byte 16 must reach the end of
  the file exactly, every type one of ``B F I M P Q A R D L C S O``. Where it breaks, the
  rest of the file (from that byte on) cannot be framed.
* **DataFlash** (messages ``0xA3 0x95 type payload``; lengths from the FMT messages, type
  128, 89 bytes): bytes that do not start a known message are skipped one at a time until
  the next header, as pymavlink does, and counted.

:func:`framing_note` turns a result into the importer's note (``lost ... bytes``) when more
than ``MAX_UNFRAMED`` of the file is not whole messages. Example::

    >>> damaged_from, size = ulog_framing(data)    # None when the chain reaches the end
"""

from __future__ import annotations

import struct

__all__ = ["MAX_UNFRAMED", "dataflash_framing", "framing_note", "ulog_framing"]

#: fraction of a file that may be unframed without a note (none: even a torn last message
#: says the file was cut).
MAX_UNFRAMED = 0.0
_ULOG_TYPES = set(b"BFIMPQARDLCSO")
_DF_HEAD = b"\xa3\x95"
_DF_FMT = 128
_DF_FMT_LENGTH = 89


def ulog_framing(data: bytes) -> tuple[int | None, int]:
    """(first byte that is not part of a whole message, or None; file size)."""
    size = len(data)
    at = 16
    while at < size:
        if at + 3 > size:
            return at, size
        length, kind = struct.unpack_from("<HB", data, at)
        if kind not in _ULOG_TYPES or length == 0 or at + 3 + length > size:
            return at, size
        at += 3 + length
    return None, size


def dataflash_framing(data: bytes) -> tuple[int, int | None, int]:
    """(bytes skipped, first skipped byte or None, file size)."""
    lengths = {_DF_FMT: _DF_FMT_LENGTH}
    size, at, skipped, first = len(data), 0, 0, None
    while at + 3 <= size:
        kind = data[at + 2]
        if data[at:at + 2] == _DF_HEAD and kind in lengths and at + lengths[kind] <= size:
            if kind == _DF_FMT:
                new_type, new_length = data[at + 3], data[at + 4]
                if new_length >= 3:
                    lengths[new_type] = new_length
            at += lengths[kind]
            continue
        nxt = data.find(_DF_HEAD, at + 1)
        nxt = size if nxt < 0 else nxt
        if first is None:
            first = at
        skipped += nxt - at
        at = nxt
    if at < size:
        skipped += size - at
        first = at if first is None else first
    return skipped, first, size


def framing_note(path, fmt: str, data: bytes) -> str | None:
    """A note naming the bytes lost when over ``MAX_UNFRAMED`` of the file is not whole
    messages; None otherwise."""
    if fmt == "ulog":
        start, size = ulog_framing(data)
        if start is None or size - start <= MAX_UNFRAMED * size:
            return None
        return (f"{path}: ULog framing: lost bytes {start}-{size} of {size} "
                f"({100 * (size - start) / size:.1f} %): the message chain breaks there "
                "(truncated or damaged); what the flight logged after it is missing")
    skipped, first, size = dataflash_framing(data)
    if skipped <= MAX_UNFRAMED * size:
        return None
    return (f"{path}: DataFlash framing: lost {skipped} of {size} bytes "
            f"({100 * skipped / size:.1f} %) that are not whole messages, from byte {first} "
            "on (damaged or truncated); messages there are missing")
