"""KLV out: `eoloc live --klv-out` re-sends the stream with each packet's first located target
in ST 0601 tags 40-42, 45, 46.

- MPEG-TS with H.264 video and KLV over UDP on loopback, out over UDP: the video comes out packet
  for packet identical (FFmpeg's demuxer through PyAV, bytes and PTS); the KLV read back by
  eoloc's reader and by a second demuxer and decoder (PyAV + stanag4609's ST 0601 decoder) carries
  the NDJSON's fix of the lowest located target id to the tags' resolution.
- Raw KLV in, to a file: every good packet the same bytes as the batch `eoloc klv --klv-out`.
"""

from __future__ import annotations

import json
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from livecmd import summary_of, until_listening, wait_for_packets, wait_until
from ports import free_udp_port

import eoloc
from eoloc.io.klv import read_klv
from eoloc.io.klv.mux import write_klv_ts
from eoloc.io.klv.reader import split_klv
from eoloc.live.sources import DatagramSink, ts_file_datagrams
from eoloc.terrain.geoid import default_geoid

MOUNTAIN = Path(eoloc.__file__).parent / "data" / "demo" / "mountain"
FLIGHT = MOUNTAIN / "flight.klv"
DEM = MOUNTAIN / "longs_peak_srtmgl3.tif"
CONFIG = MOUNTAIN / "klv.toml"
EOLOC = str(Path(sys.executable).parent / "eoloc")
# ST 0601 resolutions: tags 40/41 map +-90/+-180 deg onto int32, 42 -900..19000 m onto uint16,
# 45/46 0..4095 m onto uint16
LAT_RES, LON_RES, H_RES, CE_RES = 180 / (2**32 - 2), 360 / (2**32 - 2), 19900 / 65535, 4095 / 65535


def _packets_per_pid(ts: bytes) -> dict[int, int]:
    cells = np.frombuffer(ts[:len(ts) - len(ts) % 188], np.uint8).reshape(-1, 188)
    pids, counts = np.unique((cells[:, 1].astype(int) & 0x1F) << 8 | cells[:, 2], return_counts=True)
    return dict(zip(pids.tolist(), counts.tolist(), strict=True))


def _av_packets(path: Path) -> dict[str, list[tuple[bytes, int]]]:
    import av

    out: dict[str, list] = {"video": [], "data": []}
    with av.open(str(path)) as c:
        for p in c.demux():
            if p.size:
                out[p.stream.type].append((bytes(p), p.pts))
    return out


def _stanag_fields(data: bytes) -> list[dict[int, object]]:
    from stanag4609.klv.stream import KLVStreamParser
    from stanag4609.st0601 import ST0601_KEY, FieldDecodingMode, decode_uas_local_set

    parser = KLVStreamParser(key_prefix=ST0601_KEY, max_value_length=1 << 20)
    out = []
    for p in parser.feed(data) + parser.finish():
        try:
            fields = decode_uas_local_set(p, field_decoding=FieldDecodingMode.PRESERVE).fields
            out.append({f.item.tag: f.value for f in fields})
        except Exception:  # the demo's packet with a broken checksum: refused by the strict decoder
            out.append({})
    return out


def _lowest_fixes(ndjson: Path) -> dict[str, dict]:
    """Per ST 0601 time stamp, the fix of the lowest target id located (what --klv-out writes)."""
    best: dict[str, dict] = {}
    for line in ndjson.read_text(encoding="utf-8").splitlines():
        f = json.loads(line)
        p = f["properties"]
        if p["what"] == "target" and p["status"] == "OK":
            t = p["time_utc"]
            if t not in best or str(p["target_id"]) < str(best[t]["properties"]["target_id"]):
                best[t] = f
    return best


def test_ts_with_video_over_udp_keeps_the_video_and_carries_the_fixes(tmp_path):
    src = write_klv_ts(tmp_path / "in.ts", [split_klv(FLIGHT.read_bytes())], video_fps=10)
    rx_port, tx_port = free_udp_port(), free_udp_port()
    sink = DatagramSink(f"udp://127.0.0.1:{rx_port}")
    got = sink.datagrams
    ndjson = tmp_path / "live.ndjson"
    proc = subprocess.Popen([EOLOC, "live", f"udp://127.0.0.1:{tx_port}", "--dem", str(DEM), "--config", str(CONFIG),
                             "--klv-out", f"udp://127.0.0.1:{rx_port}", "--ndjson", str(ndjson)],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    head = until_listening(proc)  # the receiver is bound
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    for datagram, _ in ts_file_datagrams(src.read_bytes()):
        tx.sendto(datagram, ("127.0.0.1", tx_port))
        time.sleep(0.002)
    wait_for_packets(ndjson, 39, proc)  # (the first packets wait for the compiled kernels)
    # every transport packet passed on (the video after the last KLV too) before it is stopped: as
    # many on each PID as came in (the KLV's own PES only grow by the tags written into them)
    wanted = _packets_per_pid(src.read_bytes())
    wait_until(lambda: all(_packets_per_pid(b"".join(list(got))).get(pid, 0) >= n for pid, n in wanted.items()),
               f"the transport packets passed on ({sum(wanted.values())} in)")
    proc.send_signal(signal.SIGINT)
    log, _ = proc.communicate(timeout=30)
    log = head + log
    sink.stop()
    assert proc.returncode == 0 and "Traceback" not in log, log
    summary = summary_of(log)
    assert summary["packets"] == 39 and summary["klv_out"]["with_target"] == 39, log
    assert all(len(d) % 188 == 0 and d[0] == 0x47 for d in got)
    out = tmp_path / "out.ts"
    out.write_bytes(b"".join(got))

    a, b = _av_packets(src), _av_packets(out)
    assert len(a["video"]) > 300 and b["video"] == a["video"]  # every video packet untouched, with its PTS
    assert [p for _, p in b["data"]] == [p for _, p in a["data"]]  # the KLV keeps its presentation times
    # eoloc's reader on the output: every packet kept, the corrupt one still corrupt
    ours = read_klv(out)
    assert ours.n_good == 39 and ours.n_bad == 1
    best = _lowest_fixes(ndjson)
    assert len(best) == 39
    geoid = default_geoid()
    # a second demuxer (FFmpeg) and decoder (stanag4609)
    theirs = [f for data, _ in b["data"] for f in _stanag_fields(data)]
    assert sum(bool(f) for f in theirs) == 39
    by_time = {}
    for f in theirs:
        if f:
            by_time[f[2].strftime("%Y-%m-%dT%H:%M:%S.%f")[:-3] + "Z"] = f
    for pkt in ours.packets:
        t = pkt.fields[2].strftime("%Y-%m-%dT%H:%M:%S.%f")[:-3] + "Z"
        fix = best[t]
        lon, lat, h = fix["geometry"]["coordinates"]
        h_msl = h - float(geoid.undulation(lat, lon))  # the flight sends no tag 78: tag 42 is MSL
        for fields in (pkt.fields, by_time[t]):
            assert abs(fields[40] - lat) <= LAT_RES and abs(fields[41] - lon) <= LON_RES
            assert abs(fields[42] - h_msl) <= H_RES / 2 + 1e-9
            assert abs(fields[45] - fix["properties"]["ce90_m"]) <= CE_RES / 2 + 1e-9
            assert abs(fields[46] - fix["properties"]["le90_m"]) <= CE_RES / 2 + 1e-9
        # every other item as it came: the packet is the input's plus the new tags
    src_fields = {p.fields[2]: p.fields for p in read_klv(src).packets}
    for pkt in ours.packets:
        before = src_fields[pkt.fields[2]]
        assert {k: v for k, v in pkt.fields.items() if k not in (40, 41, 42, 45, 46)} == \
            {k: v for k, v in before.items() if k not in (40, 41, 42, 45, 46)}


def test_raw_klv_to_a_file_equals_the_batch_klv_out(tmp_path):
    live_out, batch_out = tmp_path / "live.klv", tmp_path / "batch.klv"
    r = subprocess.run([EOLOC, "live", str(FLIGHT), "--dem", str(DEM), "--config", str(CONFIG), "--klv-out",
                        str(live_out)], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr
    r = subprocess.run([EOLOC, "klv", str(FLIGHT), "--dem", str(DEM), "--config", str(CONFIG), "--out",
                        str(tmp_path / "batch"), "--no-map", "--klv-out", str(batch_out)],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    live, batch = read_klv(live_out), read_klv(batch_out)
    # every good packet the same bytes; the packet with a broken checksum relayed as it came (the
    # batch file leaves it out)
    assert [p.raw for p in live.packets] == [p.raw for p in batch.packets]
    assert live.n_bad == read_klv(FLIGHT).n_bad == 1 and batch.n_bad == 0
    assert [p.raw for p in live.packets] != [p.raw for p in read_klv(FLIGHT).packets]
    assert np.array_equal([p.fields.get(40) is not None for p in live.packets], [True] * 39)


def test_klv_out_destinations_are_checked(tmp_path):
    for dest, words in (("http://x:1", "udp://HOST:PORT"), (str(tmp_path / "no" / "such" / "dir" / "f.klv"),
                                                           "cannot write there")):
        r = subprocess.run([EOLOC, "live", str(FLIGHT), "--klv-out", dest], capture_output=True, text=True,
                           timeout=60)
        assert r.returncode != 0 and words in r.stderr and "Traceback" not in r.stderr, r.stderr
