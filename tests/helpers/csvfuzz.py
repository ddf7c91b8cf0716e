"""Fuzzed detection CSV files whose good records are known in advance: the oracle of the CSV
reader's "every good line kept" (issue 46 item 6), independent of eoloc (the files are written
here, byte by byte, from the records). Shared by the test suite and ``bench/bench_hostile.py``.

Each file has the header ``time_s,target_id,u_px,v_px`` and good records (time, id, u, v), with
oddities drawn from a seeded generator: line ends (LF, CRLF, CR alone, mixed), a UTF-8 BOM, no
final line end, quoted ids (commas, doubled quotes, line breaks), ids of 100-300 KiB, spaces
around values; and bad lines mixed in (wrong field counts, only commas, bytes that are not UTF-8,
an unterminated quote, text where the time goes), comments and blank lines. ``expected`` is what
a reader that keeps every good record must return; ``bad`` how many bad lines it must report."""

from __future__ import annotations

import random
from dataclasses import dataclass


@dataclass
class FuzzedCsv:
    data: bytes
    expected: list[tuple[float, str, float, float]]  # (time_s, target_id, u_px, v_px) of every good record
    bad: int  # lines that must be reported (and not read)


def _quote(text: str) -> str:
    return '"' + text.replace('"', '""') + '"'


def fuzzed_csv(seed: int, n_good: int = 40) -> FuzzedCsv:
    rng = random.Random(seed)
    ends = rng.choice(["\n", "\r\n", "\r", "mixed"])
    quotes = rng.random() < 0.5
    huge = rng.random() < 0.25
    lines: list[bytes] = [b"time_s,target_id,u_px,v_px"]
    expected, bad = [], 0
    for k in range(n_good):
        t, u, v = round(k * 0.5 + rng.random() * 0.1, 6), rng.uniform(0, 1279), rng.uniform(0, 719)
        tid = f"T{rng.randrange(1000)}"
        if quotes and rng.random() < 0.3:
            tid = rng.choice([f"{tid},with comma", f'{tid} "quoted"', f"{tid}\nline two", f'{tid}, "both"\nend'])
        if huge and k == n_good // 2:
            tid = "H" * rng.randrange(100_000, 300_000)
        cell = _quote(tid) if any(c in tid for c in ',"\n') else tid
        pad = " " * rng.randrange(1, 3) if rng.random() < 0.2 else ""
        lines.append(f"{pad}{t!r}{pad},{cell},{u!r},{pad}{v!r}".encode())
        expected.append((t, tid, u, v))
        if rng.random() < 0.15:  # something that is not a record
            kind = rng.randrange(8)
            if kind == 0:
                lines.append(b"")
            elif kind == 1:
                lines.append(b"# a comment, with commas")
            else:
                bad += 1
                lines.append({2: b",,,", 3: f"{t},X,1".encode(), 4: f"{t},X,1,2,3,4".encode(),
                              5: f"{t},caf\xe9,1,2".encode("latin-1"),  # not UTF-8
                              6: f'{t},"unterminated,1,2'.encode() if quotes else b",,,",
                              7: b"north,X,1,2"}[kind])  # no usable time
    body = []
    for i, line in enumerate(lines):
        end = ends if ends != "mixed" else rng.choice(["\n", "\r\n", "\r"])
        if end == "\r":  # a line break inside a quoted id is a CR too in such a file
            line = line.replace(b"\n", b"\r")
        body.append(line)
        if i < len(lines) - 1 or rng.random() < 0.7:
            body.append(end.encode())
    data = (b"\xef\xbb\xbf" if rng.random() < 0.2 else b"") + b"".join(body)
    return FuzzedCsv(data, expected, bad)
