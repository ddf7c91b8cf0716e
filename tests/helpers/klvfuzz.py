"""Mutated MISB ST 0601 packets with valid checksums: what a buggy or hostile encoder can send and
a receiver must survive (issue 46). Shared by the test suite and ``bench/bench_hostile.py``.

Each packet is a real one (the bundled mountain flight) whose items are changed at random and
framed again with a correct checksum, so that the mutation reaches the item decoders instead of
being stopped by the checksum: values replaced by random bytes or by all ones (time stamps past
datetime's range), lengths changed, items dropped, repeated or added with unknown tags, the
VMTI set's own items (its time stamp, its target pack) mutated the same way."""

from __future__ import annotations

import random

from eoloc.io.klv.encode import build_uas_packet, uas_items
from eoloc.io.klv.localset import encode_items, parse_items

NESTED = (74,)  # VMTI: a local set inside the packet, mutated item by item too


def _mutate_value(rng: random.Random, value: bytes) -> bytes:
    kind = rng.randrange(7)
    if kind == 0:
        return bytes(rng.randrange(256) for _ in range(len(value)))
    if kind == 1:
        return b"\xff" * len(value)
    if kind == 2:
        return b"\xff" * 8  # the time stamp that broke `eoloc live` (any tag: 8 bytes of ones)
    if kind == 3:
        return value[:rng.randrange(len(value) + 1)]
    if kind == 4:
        return value + bytes(rng.randrange(256) for _ in range(rng.randrange(1, 9)))
    if kind == 5:
        return b""
    return bytes([rng.randrange(256)]) + value[1:]


def _mutate_items(rng: random.Random, items: list[tuple[int, bytes]], depth: int = 0) -> list[tuple[int, bytes]]:
    items = list(items)
    for _ in range(rng.randrange(1, 4)):
        if not items:
            break
        k = rng.randrange(len(items))
        tag, value = items[k]
        op = rng.randrange(6)
        if tag in NESTED and depth == 0 and op < 3:
            try:
                inner, _ = parse_items(value)
            except Exception:
                inner = []
            items[k] = (tag, encode_items(_mutate_items(rng, inner, depth + 1)))
        elif op < 3:
            items[k] = (tag, _mutate_value(rng, value))
        elif op == 3:
            del items[k]
        elif op == 4:
            items.insert(rng.randrange(len(items) + 1), (tag, _mutate_value(rng, value)))  # the tag twice
        else:
            items.append((rng.choice([0x7F, 0x80, 200, 1000]), bytes(rng.randrange(256) for _ in range(4))))
    return items


def mutated_packets(good: list[bytes], n: int, seed: int = 0) -> list[bytes]:
    """``n`` packets, each a packet of ``good`` with random item mutations and a valid checksum."""
    rng = random.Random(seed)
    out = []
    for k in range(n):
        items = [(t, v) for t, v in uas_items(good[k % len(good)]) if t != 1]  # (the checksum is rebuilt)
        out.append(build_uas_packet(_mutate_items(rng, items)))
    return out


def with_reserved_null_cell(ts: bytes) -> bytes:
    """An MPEG-TS with one null packet whose adaptation_field_control is the reserved 00 slipped
    in halfway (at a 188-byte boundary): a stream the vectorised demultiplexer calls unclean, so
    the reader takes its tolerant path, with nothing of the KLV or its timing changed."""
    half = len(ts) // 188 // 2 * 188
    return ts[:half] + b"\x47\x1f\xff\x00" + b"\xff" * 184 + ts[half:]
