"""Compiled KLV local-set scanning: MISB ST 0601 packets (with their ST 0903 VMTI sets) framed,
checked and decoded straight into column arrays, one pass over the bytes.

This module holds no tag table: :mod:`eoloc.io.klv.columnar` builds the tables from the very
decoders the tolerant reader uses (:data:`eoloc.io.klv.st0601.FIELDS`, ST 0903's tables) and passes
them in as arrays, one row per tag (``SPEC_*`` columns, item kinds ``K_*``).

The scanner decodes only what it can decode *exactly as the tolerant reader would without a
note*: a packet is "clean" when every item is in its standard form (short or needed long-form
lengths, no repeated tag, the time stamp first, every mapped item of its standard length, text
in ASCII, a VMTI set of version 4 or later whose target count agrees). Anything else (a note, a
value the reader would refuse) makes the packet unclean, and the caller hands that packet to the
tolerant reader; framing that is not a clean run of ST 0601 packets stops the run. So the scanner
is a fast path, never a second opinion.
"""

from __future__ import annotations

import numpy as np
from numba import njit

# item kinds (column SPEC_KIND of a table)
K_RAW, K_MAPPED, K_TIME, K_TEXT_UTF8, K_UINT, K_VMTI, K_IRREGULAR, K_VERSION = 0, 1, 2, 3, 4, 5, 6, 7
K_TEXT_ANY, K_IMAPB, K_LOCATION, K_SERIES, K_IGNORE = 8, 9, 10, 11, 12
# integer columns of a table
SPEC_KIND, SPEC_COL, SPEC_LENGTH, SPEC_SIGNED, SPEC_HAS_SPECIAL, SPEC_SPECIAL, SPEC_RMIN = 0, 1, 2, 3, 4, 5, 6
SPEC_TOP, SPEC_EXACT_TOP, SPEC_ULO, SPEC_UHI = 7, 8, 9, 10
N_SPEC_I = 11
# float columns of a table
SPEC_LO, SPEC_STEP, SPEC_ZERO = 0, 1, 2
N_SPEC_F = 3
N_TAGS = 128  # tags of one BER-OID byte have table rows; longer tags are unknown items
MAX_TAG = 16384  # tags of at most 2 BER-OID bytes are checked for repeats; longer ones make a packet unclean
# target columns: integers (packet row, target id, centroid, box corners, centroid row and column, 1 where
# a location pack is sent; -1: absent)
T_ROW, T_ID, T_LOC = 0, 1, 7
N_TARGET_I, N_TARGET_F = 8, 6  # floats: offset lat/lon, HAE, location lat/lon/HAE (NaN: absent)
# per-packet VMTI columns (floats: the items the VMTI table gives a column; NaN absent)
N_VMTI_F = 4

_JIT = {"cache": True, "nogil": True, "error_model": "numpy"}


@njit(forceinline=True, **_JIT)
def ber_length(buf, pos, end):
    """(length, position after it, long form where short would do, readable) of a BER length."""
    if pos >= end:
        return 0, pos, False, False
    first = np.int64(buf[pos])
    if first < 0x80:
        return first, pos + 1, False, True
    n = first & 0x7F
    if n == 0 or n > 8 or pos + 1 + n > end:
        return 0, pos, False, False
    length = np.int64(0)
    for i in range(pos + 1, pos + 1 + n):
        length = np.int64(1) << 56 if length > (np.int64(1) << 48) else length * 256 + np.int64(buf[i])
    return length, pos + 1 + n, length < 0x80 or buf[pos + 1] == 0, True


@njit(forceinline=True, **_JIT)
def ber_oid(buf, pos, end):
    """(value, position after it, readable) of a BER-OID integer of at most 4 bytes."""
    value = np.int64(0)
    for i in range(pos, min(pos + 4, end)):
        b = np.int64(buf[i])
        value = value * 128 + (b & 0x7F)
        if b < 0x80:
            return value, i + 1, True
    return np.int64(0), pos, False


@njit(forceinline=True, **_JIT)
def read_uint(buf, p, n):
    v = np.int64(0)
    for i in range(p, p + n):
        v = v * 256 + np.int64(buf[i])
    return v


@njit(forceinline=True, **_JIT)
def field_value(buf, p, n, spec_i, spec_f, tag, empty_unknown, max_time_us):
    """(clean, float value, integer value) of one item by its table row; an empty item of a table
    tag is 'unknown' (NaN) where ``empty_unknown`` (ST 0601 §6.2)."""
    kind = spec_i[tag, SPEC_KIND]
    if kind == K_RAW or kind == K_IGNORE or kind == K_TEXT_ANY:
        return True, np.nan, np.int64(-1)
    if n == 0 and empty_unknown and kind != K_VMTI and kind != K_IRREGULAR:
        return True, np.nan, np.int64(-1)
    if kind == K_MAPPED:
        return mapped_value(buf, p, n, spec_i, spec_f, tag)
    if kind == K_TIME:
        if n != 8 or buf[p] >= 0x80:
            return False, np.nan, np.int64(-1)
        us = read_uint(buf, p, n)
        if us > max_time_us:
            return False, np.nan, np.int64(-1)
        return True, np.nan, us
    if kind == K_TEXT_UTF8:
        for i in range(p, p + n):
            if buf[i] >= 0x80:  # (maybe valid UTF-8: the tolerant reader says)
                return False, np.nan, np.int64(-1)
        return True, np.nan, np.int64(-1)
    if kind == K_UINT or kind == K_VERSION:
        return uint_value(buf, p, n, spec_i, tag, kind == K_VERSION)
    if kind == K_IMAPB:
        if n != spec_i[tag, SPEC_LENGTH]:
            return False, np.nan, np.int64(-1)
        return True, imapb(buf, p, n, spec_i, spec_f, tag), np.int64(-1)
    return False, np.nan, np.int64(-1)  # K_VMTI, K_SERIES, K_LOCATION: read by their callers; K_IRREGULAR


@njit(forceinline=True, **_JIT)
def uint_value(buf, p, n, spec_i, tag, one_byte):
    """(clean, value, value) of an unsigned integer item of 1 to 8 bytes (1 where ``one_byte``)
    within its table row's bounds."""
    if n < 1 or n > 8 or (n == 8 and buf[p] >= 0x80) or (one_byte and n > 1):
        return False, np.nan, np.int64(-1)
    v = read_uint(buf, p, n)
    if v < spec_i[tag, SPEC_ULO] or (spec_i[tag, SPEC_UHI] >= 0 and v > spec_i[tag, SPEC_UHI]):
        return False, np.nan, np.int64(-1)
    return True, float(v), v


@njit(forceinline=True, **_JIT)
def mapped_value(buf, p, n, spec_i, spec_f, tag):
    """(clean, value, raw) of an ST 0601 mapped item (ST 0601 §6.5; its special raw value NaN)."""
    if n != spec_i[tag, SPEC_LENGTH]:
        return False, np.nan, np.int64(-1)
    r = read_uint(buf, p, n)
    if spec_i[tag, SPEC_SIGNED] and r >= (np.int64(1) << (8 * n - 1)):
        r -= np.int64(1) << (8 * n)
    if spec_i[tag, SPEC_HAS_SPECIAL] and r == spec_i[tag, SPEC_SPECIAL]:
        return True, np.nan, r
    return True, spec_f[tag, SPEC_LO] + (r - spec_i[tag, SPEC_RMIN]) * spec_f[tag, SPEC_STEP], r


@njit(forceinline=True, **_JIT)
def imapb(buf, p, n, spec_i, spec_f, tag):
    y = read_uint(buf, p, n)
    top = spec_i[tag, SPEC_TOP]
    if y >= top and not (spec_i[tag, SPEC_EXACT_TOP] and y == top):
        return np.nan
    return spec_f[tag, SPEC_STEP] * (y - spec_f[tag, SPEC_ZERO]) + spec_f[tag, SPEC_LO]


@njit(**_JIT)
def frame_run(buf, pos, limit, key):
    """The run of back-to-back ST 0601 packets from ``pos`` whose framing and checksum are good
    (at most ``limit``): (count, key offsets, value starts, ends). The run stops at the first
    position that is not such a packet."""
    size = buf.size
    starts = np.empty(limit, np.int64)
    vstarts = np.empty(limit, np.int64)
    ends = np.empty(limit, np.int64)
    n = 0
    while n < limit and pos + 16 < size:
        for j in range(16):
            if buf[pos + j] != key[j]:
                return n, starts, vstarts, ends
        length, start, _, ok = ber_length(buf, pos + 16, size)
        if not ok or length > size - start:
            break
        end = start + length
        if end - pos < 20 or buf[end - 4] != 1 or buf[end - 3] != 2:
            break
        even = np.int64(0)
        odd = np.int64(0)
        for i in range(pos, end - 2, 2):
            even += buf[i]
        for i in range(pos + 1, end - 2, 2):
            odd += buf[i]
        if ((even << 8) + odd) & 0xFFFF != np.int64(buf[end - 2]) * 256 + np.int64(buf[end - 1]):
            break
        starts[n], vstarts[n], ends[n] = pos, start, end
        n += 1
        pos = end
    return n, starts, vstarts, ends


@njit(**_JIT)
def grow(a, need):
    """The 2-D ``a`` with at least ``need`` rows (doubling), its rows kept."""
    if need <= a.shape[0]:
        return a
    b = np.empty((max(need, 2 * a.shape[0]), a.shape[1]), a.dtype)
    b[:a.shape[0]] = a
    return b


@njit(forceinline=True, **_JIT)
def scan_set(buf, p, end, stamp, serial):
    """Check that the items of the set buf[p:end] tile it in standard form (readable tags of at
    most 2 bytes, no needless long-form length, no repeated tag): (clean, count of items)."""
    count = 0
    while p < end:
        tag, q, ok = ber_oid(buf, p, end)
        if not ok or tag >= MAX_TAG:
            return False, count
        length, q, needless, ok = ber_length(buf, q, end)
        if not ok or needless or length > end - q:
            return False, count
        if stamp[tag] == serial:
            return False, count
        stamp[tag] = serial
        p = q + length
        count += 1
    return True, count


@njit(**_JIT)
def decode_targets(buf, p, end, tables, row, tg_i, tg_f, ntg, stamp, serial, max_time_us):
    """The VTarget packs of a series into target rows: (clean, rows after, serial after)."""
    spec_i, spec_f, lspec_i, lspec_f = tables[4], tables[5], tables[6], tables[7]
    while p < end:
        length, q, _, ok = ber_length(buf, p, end)
        if not ok or length > end - q:
            return False, ntg, serial
        pack_end = q + length
        tid, q, ok = ber_oid(buf, q, pack_end)
        if not ok:
            return False, ntg, serial
        serial += 1
        ok, _ = scan_set(buf, q, pack_end, stamp, serial)
        if not ok:
            return False, ntg, serial
        tg_i[ntg, :] = -1
        tg_f[ntg, :] = np.nan
        tg_i[ntg, T_ROW] = row
        tg_i[ntg, T_ID] = tid
        while q < pack_end:
            tag, q, _ = ber_oid(buf, q, pack_end)
            n, q, _, _ = ber_length(buf, q, pack_end)
            kind = spec_i[tag, SPEC_KIND] if tag < N_TAGS else K_RAW
            col = spec_i[tag, SPEC_COL] if tag < N_TAGS else -1
            if kind == K_LOCATION:
                if n != 10 and n != 16 and n != 22:
                    return False, ntg, serial
                # lat, lon, HAE: rows 0, 1, 2 of the location pack's own IMAPB table
                tg_i[ntg, T_LOC] = 1
                tg_f[ntg, col] = imapb(buf, q, 4, lspec_i, lspec_f, 0)
                tg_f[ntg, col + 1] = imapb(buf, q + 4, 4, lspec_i, lspec_f, 1)
                tg_f[ntg, col + 2] = imapb(buf, q + 8, 2, lspec_i, lspec_f, 2)
            elif kind != K_RAW:
                if kind == K_UINT:  # (the hot case, apart: see decode_run)
                    ok, fv, iv = uint_value(buf, q, n, spec_i, tag, False)
                else:
                    ok, fv, iv = field_value(buf, q, n, spec_i, spec_f, tag, False, max_time_us)
                if not ok:
                    return False, ntg, serial
                if col >= 0:
                    if kind == K_UINT:
                        tg_i[ntg, col] = iv
                    else:
                        tg_f[ntg, col] = fv
            q += n
        ntg += 1
        p = pack_end
    return True, ntg, serial


@njit(**_JIT)
def decode_vmti(buf, p, end, tables, row, has_vmti, vm_f, tg_i, tg_f, ntg, stamp, serial, max_time_us, min_version):
    """A VMTI set (ST 0601 tag 74's value) into the packet's VMTI columns and target rows:
    (clean, target rows after, serial after)."""
    vspec_i, vspec_f = tables[2], tables[3]
    serial += 1
    ok, _ = scan_set(buf, p, end, stamp, serial)
    if not ok:
        return False, ntg, serial
    vm_f[row, :] = np.nan
    has_vmti[row] = True
    version = np.int64(-1)
    reported = np.int64(-1)
    series_p = np.int64(-1)
    series_end = np.int64(-1)
    q = p
    while q < end:
        tag, q, _ = ber_oid(buf, q, end)
        n, q, _, _ = ber_length(buf, q, end)
        kind = vspec_i[tag, SPEC_KIND] if tag < N_TAGS else K_RAW
        if kind == K_SERIES:
            series_p, series_end = q, q + n
        elif kind != K_RAW:
            ok, fv, iv = field_value(buf, q, n, vspec_i, vspec_f, tag, False, max_time_us)
            if not ok:
                return False, ntg, serial
            col = vspec_i[tag, SPEC_COL]
            if tag == 4:
                version = iv
            elif tag == 6:
                reported = iv
            if col >= 0:
                vm_f[row, col] = fv
        q += n
    if version < min_version:  # missing (a note) or ST 0903.3's mappings: the tolerant reader's
        return False, ntg, serial
    first = ntg
    if series_p >= 0:
        ok, ntg, serial = decode_targets(buf, series_p, series_end, tables, row, tg_i, tg_f, ntg, stamp, serial,
                                         max_time_us)
        if not ok:
            return False, first, serial
    if reported >= 0 and reported != ntg - first:
        return False, first, serial
    return True, ntg, serial


@njit(**_JIT)
def decode_run(buf, vstarts, ends, n, tables, n_cols, max_time_us, min_version, time_tag):
    """Decode ``n`` framed ST 0601 packets into columns: (clean, values, present, time_us, has_vmti, vm_f,
    target count, tg_i, tg_f). An unclean packet's row is left for the caller to fill. ``tables``:
    (integer, float) tables of ST 0601, the VMTI set, the VTarget pack, the location pack."""
    spec_i, spec_f = tables[0], tables[1]
    values = np.full((n, n_cols), np.nan)
    present = np.zeros((n, n_cols), np.bool_)
    time_us = np.full(n, -1, np.int64)
    clean = np.ones(n, np.bool_)
    has_vmti = np.zeros(n, np.bool_)
    vm_f = np.full((n, N_VMTI_F), np.nan)
    tg_i = np.empty((max(16, n), N_TARGET_I), np.int64)
    tg_f = np.empty((max(16, n), N_TARGET_F), np.float64)
    ntg = 0
    stamp = np.zeros(MAX_TAG, np.int64)
    serial = np.int64(0)
    for k in range(n):
        p, end = vstarts[k], ends[k] - 4
        serial += 1
        ok, count = scan_set(buf, p, end, stamp, serial)
        if not ok:
            clean[k] = False
            continue
        first_tag = np.int64(-1)
        q = p
        vmti_p = np.int64(-1)
        vmti_end = np.int64(-1)
        while q < end and ok:
            tag, q, _ = ber_oid(buf, q, end)
            m, q, _, _ = ber_length(buf, q, end)
            if first_tag < 0:
                first_tag = tag
            if tag == time_tag and first_tag != time_tag:
                ok = False
            kind = spec_i[tag, SPEC_KIND] if tag < N_TAGS else K_RAW
            if kind == K_VMTI:
                vmti_p, vmti_end = q, q + m
            elif kind != K_RAW:
                if kind == K_MAPPED and m > 0:  # (the hot case, apart: through field_value it costs 4x)
                    good, fv, iv = mapped_value(buf, q, m, spec_i, spec_f, tag)
                else:
                    good, fv, iv = field_value(buf, q, m, spec_i, spec_f, tag, True, max_time_us)
                if not good:
                    ok = False
                elif kind == K_TIME:
                    time_us[k] = iv
                elif spec_i[tag, SPEC_COL] >= 0:
                    values[k, spec_i[tag, SPEC_COL]] = fv
                    present[k, spec_i[tag, SPEC_COL]] = True
            q += m
        if ok and vmti_p >= 0:
            tg_i = grow(tg_i, ntg + (vmti_end - vmti_p) // 2 + 1)
            tg_f = grow(tg_f, tg_i.shape[0])
            ok, ntg, serial = decode_vmti(buf, vmti_p, vmti_end, tables, k, has_vmti, vm_f, tg_i, tg_f, ntg, stamp,
                                          serial, max_time_us, min_version)
        if not ok:
            clean[k] = False
            values[k, :] = np.nan
            present[k, :] = False
            time_us[k] = -1
            has_vmti[k] = False
            vm_f[k, :] = np.nan
    return clean, values, present, time_us, has_vmti, vm_f, ntg, tg_i[:ntg], tg_f[:ntg]
