"""What an Arrow IPC stream declares, read before anything in it is decompressed or allocated.

A request body of 50 KB can declare 10^8 rows, or compressed buffers that inflate to gigabytes:
pyarrow would allocate all of it while reading the stream, before eoloc could count the pixels.
So the declarations are read first, from each message's metadata (Arrow's ``Message.fbs``, a
flatbuffer: the message kind; a record batch's row count, its buffers and whether its body is
compressed) and, for a compressed body, from the 8-byte uncompressed length that starts each
buffer (Arrow's IPC format). Messages themselves come from pyarrow's ``MessageReader``, which
reads the framing and the bytes without decoding them.

Hand-written: pyarrow reads a record batch only whole, and the ``flatbuffers`` package would be
a dependency for the four fields read here; every offset is checked against the buffer's bounds.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

RECORD_BATCH = 3  # MessageHeader union: Schema 1, DictionaryBatch 2, RecordBatch 3, Tensor 4, SparseTensor 5


class MalformedMessageError(ValueError):
    """The metadata is not the flatbuffer Arrow's format says."""


@dataclass(frozen=True)
class Declared:
    """What a stream's record batches declare: rows, bytes once decompressed, compressed or not."""

    rows: int
    bytes: int
    compressed: bool


def _read(buf: bytes, fmt: str, pos: int):
    size = struct.calcsize(fmt)
    if pos < 0 or pos + size > len(buf):
        raise MalformedMessageError(f"an offset ({pos}) outside the {len(buf)}-byte metadata")
    return struct.unpack_from(fmt, buf, pos)[0]


def _table(buf: bytes, pos: int) -> tuple[int, int, int]:
    vtable = pos - _read(buf, "<i", pos)
    return pos, vtable, _read(buf, "<H", vtable)


def _field(buf: bytes, table: tuple[int, int, int], slot: int) -> int | None:
    pos, vtable, size = table
    at = 4 + 2 * slot
    if at + 2 > size:
        return None
    off = _read(buf, "<H", vtable + at)
    return pos + off if off else None


def _indirect(buf: bytes, pos: int) -> int:
    return pos + _read(buf, "<I", pos)


def record_batch(metadata: bytes) -> tuple[int, list[tuple[int, int]], bool] | None:
    """(rows, [(buffer offset, length) in the body], compressed) of a record batch message's
    metadata; None for another kind of message."""
    msg = _table(metadata, _indirect(metadata, 0))
    kind_at = _field(metadata, msg, 1)
    if kind_at is None or _read(metadata, "<B", kind_at) != RECORD_BATCH:
        return None
    header_at = _field(metadata, msg, 2)
    if header_at is None:
        raise MalformedMessageError("a record batch message without its header")
    batch = _table(metadata, _indirect(metadata, header_at))
    length_at = _field(metadata, batch, 0)
    rows = 0 if length_at is None else _read(metadata, "<q", length_at)
    buffers = []
    buffers_at = _field(metadata, batch, 2)
    if buffers_at is not None:
        vec = _indirect(metadata, buffers_at)
        for k in range(_read(metadata, "<I", vec)):
            buffers.append((_read(metadata, "<q", vec + 4 + 16 * k), _read(metadata, "<q", vec + 12 + 16 * k)))
    return rows, buffers, _field(metadata, batch, 3) is not None


def declared(body: bytes) -> Declared:
    """What the record batches of an Arrow IPC stream declare, summed, without decoding them.
    ValueError (pyarrow's ArrowInvalid is one) or :class:`MalformedMessageError` for bytes that are
    not such a stream."""
    import pyarrow as pa

    rows = size = 0
    compressed = False
    for message in pa.ipc.MessageReader.open_stream(pa.py_buffer(body)):
        batch = record_batch(message.metadata.to_pybytes())
        if batch is None:
            if message.type not in ("schema",):
                raise MalformedMessageError(f"a {message.type} message: only a schema and record batches are read")
            continue
        n, buffers, packed = batch
        if n < 0:
            raise MalformedMessageError(f"a record batch of {n} rows")
        rows += n
        data = message.body.to_pybytes() if message.body is not None else b""
        for offset, length in buffers:
            if offset < 0 or length < 0 or offset + length > len(data):
                raise MalformedMessageError(f"a buffer ({offset}, {length}) outside the {len(data)}-byte body")
            if packed and length >= 8:
                raw = struct.unpack_from("<q", data, offset)[0]  # -1: this buffer is not compressed
                size += length - 8 if raw < 0 else raw
            else:
                size += length
        compressed |= packed
    return Declared(rows, size, compressed)
