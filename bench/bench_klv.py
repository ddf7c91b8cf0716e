"""KLV decoding: packets per second for eoloc's tolerant reader against stanag4609 (strict, the
library eoloc's encoder and --strict use) and klvdata (0.0.3, the other pure-Python decoder), on
the same bytes in one run. Two streams: pose packets as a real encoder sends them (the tags of
the Esri Truck clip: 2, 5-7, 13-33, 47, 65) and the same packets with a 20-target ST 0903 VMTI set;
raw KLV and the same packets in an MPEG-TS written by libavformat. jMISB (Java) is measured on
the raw streams where it is built (`sh bench/jmisb/build.sh JMISB_CHECKOUT`; a JDK from Debian).

    python bench/bench_klv.py [--n 3000]
"""

from __future__ import annotations

import io
import tempfile
from datetime import UTC, datetime, timedelta
from fractions import Fraction
from pathlib import Path

import numpy as np

from _common import best_time, row, script


def pose_packets(n: int, *, vmti: bool = False, seed: int = 0) -> list[bytes]:
    from eoloc.io.klv import encode_uas_packet, encode_vmti

    rng = np.random.default_rng(seed)
    t0 = datetime(2026, 1, 1, tzinfo=UTC)
    out = []
    for k in range(n):
        v = {2: t0 + timedelta(seconds=k / 30), 3: "BENCH", 4: "N123", 5: float(rng.uniform(0, 360)),
             6: float(rng.uniform(-10, 10)), 7: float(rng.uniform(-30, 30)), 10: "C208", 11: "EO", 12: "WGS-84",
             13: 41.09 + 1e-4 * k, 14: -104.85, 15: 2950.0, 16: 2.5, 17: 1.4, 18: float(rng.uniform(0, 360)),
             19: float(rng.uniform(-60, -10)), 20: 0.0, 21: 2000.0, 22: 90.0, 23: 41.08, 24: -104.86, 25: 1890.0,
             **{t: 0.001 for t in range(26, 34)}, 47: 1}
        if vmti:
            v[74] = encode_vmti([(j + 1, 30.0 * j, 20.0 * j) for j in range(20)], 1280, 720)
        out.append(encode_uas_packet(v))
    return out


def ts_file(path: Path, packets: list[bytes]) -> Path:
    import av

    with av.open(str(path), "w", format="mpegts") as out:
        s = out.add_data_stream(codec_name="klv")
        for i, p in enumerate(packets):
            pkt = av.Packet(p)
            pkt.stream = s
            pkt.pts = pkt.dts = i * 3000
            pkt.time_base = Fraction(1, 90000)
            out.mux(pkt)
    return path


def stanag_decode(data: bytes) -> int:
    from stanag4609.klv.stream import KLVStreamParser
    from stanag4609.st0601 import ST0601_KEY, FieldDecodingMode, decode_uas_local_set

    parser = KLVStreamParser(key_prefix=ST0601_KEY, max_value_length=1 << 20)
    packets = parser.feed(data) + parser.finish()
    return sum(bool(decode_uas_local_set(p, field_decoding=FieldDecodingMode.PRESERVE).fields) for p in packets)


def stanag_ts(data: bytes) -> int:
    from stanag4609.transport.demux import PESStreamEvent, StreamKind, TransportDemuxer

    demux = TransportDemuxer(recover_transport=True)
    buf = b"".join(ev.pes.payload for ev in demux.feed(data) + demux.finish()
                   if isinstance(ev, PESStreamEvent) and ev.kind is StreamKind.KLV)
    return stanag_decode(buf)


def klvdata_decode(data: bytes) -> int:
    import klvdata

    return sum(bool(p.MetadataList()) for p in klvdata.StreamParser(data))


def main(n: int = 3000) -> list[str]:
    from eoloc.io.klv import decode_klv_bytes, read_klv
    from eoloc.io.klv.columnar import read_klv_columns

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for vmti in (False, True):
            packets = pose_packets(n, vmti=vmti)
            data = b"".join(packets)
            assert decode_klv_bytes(data).n_good == n and stanag_decode(data) == n
            what = f"{n} ST 0601 packets{' + 20-target VMTI' if vmti else ''}"
            t_e = best_time(lambda d=data: decode_klv_bytes(d), repeat=3)
            t_s = best_time(lambda d=data: stanag_decode(d), repeat=3)
            rows.append(row(f"KLV decode, raw: {what}", f"{n / t_e:,.0f} packets/s", f"stanag4609 {n / t_s:,.0f}/s",
                            t_s / t_e))
            if not vmti:  # klvdata has no ST 0903
                assert klvdata_decode(data) == n
                t_k = best_time(lambda d=data: klvdata_decode(d), repeat=3)
                rows.append(row(f"KLV decode, raw: {what}", f"{n / t_e:,.0f} packets/s", f"klvdata {n / t_k:,.0f}/s",
                                t_k / t_e))
            rows += columnar_rows(what, data, n, t_e, t_s, t_k if not vmti else None)
            ts = ts_file(Path(tmp) / f"s{int(vmti)}.ts", packets)
            raw = ts.read_bytes()
            assert read_klv(ts).n_good == n and stanag_ts(raw) == n
            t_e = best_time(lambda p=ts: read_klv(p), repeat=3)
            t_s = best_time(lambda d=raw: stanag_ts(d), repeat=3)
            rows.append(row(f"KLV decode, MPEG-TS: {what}", f"{n / t_e:,.0f} packets/s",
                            f"stanag4609 demux + decode {n / t_s:,.0f}/s", t_s / t_e))
            t_c = best_time(lambda p=ts: read_klv_columns(p), repeat=3)
            rows.append(row(f"KLV decode to columns, MPEG-TS: {what}", f"{n / t_c:,.0f} packets/s",
                            f"stanag4609 demux + decode {n / t_s:,.0f}/s", t_s / t_c))
        rows += video_ts_row(Path(tmp), pose_packets(n // 10))
        rows.append(klv_out_row(pose_packets(n // 3)))
    return rows


def columnar_rows(what: str, data: bytes, n: int, t_tolerant: float, t_stanag: float,
                  t_klvdata: float | None) -> list[str]:
    """The columnar reader (issue 54: compiled scanner, tolerant reader for what it declines) on
    the same packets 10 times over (its rate is per packet; the peers' per-packet times come from
    the n-packet stream above, where they take seconds), against the tolerant reader of today,
    stanag4609 and klvdata."""
    from eoloc.io.klv.columnar import decode_klv_columns

    big = data * 10
    cols = decode_klv_columns(big)  # (and compiles, or loads the cache)
    assert len(cols) == 10 * n and cols.scanned == 10 * n
    t_c = best_time(lambda: decode_klv_columns(big), repeat=3) / 10
    out = [row(f"KLV decode to columns, raw: {what} (x10)", f"{n / t_c:,.0f} packets/s",
               f"eoloc tolerant reader {n / t_tolerant:,.0f}/s", t_tolerant / t_c),
           row(f"KLV decode to columns, raw: {what} (x10)", f"{n / t_c:,.0f} packets/s",
               f"stanag4609 {n / t_stanag:,.0f}/s", t_stanag / t_c)]
    if t_klvdata is not None:
        out.append(row(f"KLV decode to columns, raw: {what} (x10)", f"{n / t_c:,.0f} packets/s",
                       f"klvdata {n / t_klvdata:,.0f}/s", t_klvdata / t_c))
    t_j = jmisb_seconds(big, 10 * n)
    if t_j is not None:
        out.append(row(f"KLV decode to columns, raw: {what} (x10)", f"{n / t_c:,.0f} packets/s",
                       f"jMISB {n / (t_j / 10):,.0f}/s (Java, JIT-warmed)", (t_j / 10) / t_c))
    return out


JMISB = Path(__file__).parent / "jmisb" / "build" / "classes"


def jmisb_seconds(data: bytes, n: int) -> float | None:
    """jMISB's best time (s) to parse ``data`` (``n`` raw KLV packets), in a JVM after a JIT
    warm-up (`bench/jmisb/Bench.java`); None where it is not built (`sh bench/jmisb/build.sh
    JMISB_CHECKOUT`) or no JVM is installed."""
    import shutil
    import subprocess

    if not JMISB.is_dir() or shutil.which("java") is None:
        return None
    with tempfile.NamedTemporaryFile(suffix=".klv") as f:
        f.write(data)
        f.flush()
        cp = f"{JMISB}:/usr/share/java/slf4j-api.jar:/usr/share/java/slf4j-nop.jar"
        done = subprocess.run(["java", "-cp", cp, "Bench", f.name, "5"], capture_output=True, text=True, check=True)
    count, seconds, _ = done.stdout.split()
    assert int(count) == n, (count, n)  # every packet parsed
    return float(seconds)


def video_ts_row(tmp: Path, packets: list[bytes]) -> list[str]:
    """KLV out of a transport stream that also carries H.264 video (most of its transport packets),
    as a recording is: the reader with its vectorised demultiplexing of a clean stream
    (`demux.clean_klv_payloads`) against the same reader through KLVDemux (the reader before it,
    `fast=False`) and stanag4609's demultiplexer and decoder, the same file."""
    from eoloc.io.klv.columnar import read_klv_columns
    from eoloc.io.klv.mux import write_klv_ts
    from eoloc.io.klv.reader import decode_klv_bytes, read_klv, ts_klv_parts
    from eoloc.io.klv.segments import klv_segments

    n = len(packets)
    rng = np.random.default_rng(54)
    noise = rng.integers(0, 256, (8, 360, 640), dtype=np.uint8)  # (pictures that do not compress to nothing)
    ts = write_klv_ts(tmp / "video.ts", [[(p, k / 30) for k, p in enumerate(packets)]], video_fps=30,
                      video_size=(640, 360), frame_source=lambda i: noise[i % 8])
    data = ts.read_bytes()
    assert read_klv(ts).n_good == n and stanag_ts(data) == n
    t_e = best_time(lambda: read_klv(ts), repeat=3)
    t_o = best_time(lambda: ts_klv_parts(data, str(ts), strict=False, decode=decode_klv_bytes, fast=False), repeat=3)
    t_s = best_time(lambda: stanag_ts(data), repeat=3)
    cells = len(data) // 188
    assert sum(len(s) for s in klv_segments(ts, ts_chunk_bytes=1_000_000)) == n
    t_c = best_time(lambda: read_klv_columns(ts), repeat=3)
    t_g = best_time(lambda: [len(s) for s in klv_segments(ts, ts_chunk_bytes=1_000_000)], repeat=3)
    size = len(data) / 1e6
    return [row(f"KLV out of an MPEG-TS with 640x360 H.264 video ({cells:,} transport packets, {n} KLV packets)",
                f"{cells / t_e:,.0f} transport packets/s ({t_e * 1e3:.0f} ms)",
                f"the reader through KLVDemux (before) {t_o * 1e3:.0f} ms; stanag4609 {t_s * 1e3:.0f} ms",
                t_o / t_e),
            row(f"the same streamed ({size:.0f} MB: the archive's reader, the transport read 1 MB at a time, the "
                "KLV set aside, then decoded to columns)",
                f"{cells / t_g:,.0f} transport packets/s ({t_g * 1e3:.0f} ms)",
                f"read whole to columns {t_c * 1e3:.0f} ms", t_c / t_g)]


def klv_out_row(packets: list[bytes]) -> str:
    """--klv-out: a fix written into each packet item by item (eoloc) against stanag4609 re-encoding
    the whole packet with the same five items (what eoloc did before), the same packets."""
    from stanag4609.st0601 import update_uas_local_set

    from eoloc.io.klv.encode import with_target_location

    fix = {40: 41.1, 41: -104.8, 42: 1900.5, 45: 12.0, 46: 7.5}
    from stanag4609.klv import iter_klv, parse_local_set

    def items(packet: bytes) -> dict:
        (k,) = list(iter_klv(io.BytesIO(packet)))
        return {i.tag: i.value for i in parse_local_set(k.value, canonical=False).items if i.tag != 1}

    for p in packets[:3]:  # the same items either way (the order aside)
        assert items(update_uas_local_set(p, fix)) == items(with_target_location(p, 41.1, -104.8, 1900.5, ce90_m=12.0,
                                                                                le90_m=7.5))
    t_e = best_time(lambda: [with_target_location(p, 41.1, -104.8, 1900.5, ce90_m=12.0, le90_m=7.5)
                             for p in packets], repeat=3)
    t_s = best_time(lambda: [update_uas_local_set(p, fix) for p in packets], repeat=3)
    n = len(packets)
    return row(f"--klv-out: a fix into {n} ST 0601 packets", f"{n / t_e:,.0f} packets/s",
               f"stanag4609 whole-packet re-encode {n / t_s:,.0f}/s", t_s / t_e)


if __name__ == "__main__":
    script(main, __doc__, flag="--n", kind=int, default=3000, help_text="packets per stream (default 3000)")
