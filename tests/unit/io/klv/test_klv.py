"""MISB ST 0601 / ST 0903 in: decoder against published values, robustness (fuzzed), MPEG-TS from an
independent muxer (libavformat via PyAV), the ST 0601 pointing convention against an independent
chain (scipy rotations + pymap3d), VMTI targets located back to known points."""

from __future__ import annotations

import os
from datetime import UTC, datetime
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pymap3d.los import lookAtSpheroid
from scipy.spatial.transform import Rotation
from where import DATA

import eoloc
from eoloc.geodesy import horizontal_distance_m
from eoloc.ground.frame import frame_geometry, misb_sensor, packet_heights, packet_pose
from eoloc.io.klv import (
    UAS_KEY,
    decode_klv_bytes,
    encode_uas_packet,
    encode_vmti,
    klv_telemetry,
    read_klv,
    vmti_detections,
)
from eoloc.jobs.klvframes import locate_vmti
from eoloc.sensor import Camera, Pose, SensorModel
from eoloc.terrain.geoid import default_geoid

KLVS = DATA / "klv"


def _split(data: bytes) -> list[bytes]:
    """The packets of a clean stream (independent of the reader: key + BER length)."""
    out, pos = [], 0
    while pos < len(data):
        assert data[pos:pos + 16] == UAS_KEY
        b = data[pos + 16]
        n, used = (b, 1) if b < 0x80 else (int.from_bytes(data[pos + 17:pos + 17 + (b & 0x7F)], "big"), 1 + (b & 0x7F))
        end = pos + 16 + used + n
        out.append(data[pos:end])
        pos = end
    return out


def _bcc16(packet: bytes) -> int:
    """ST 0601 checksum written out from the standard: 16-bit sum of the packet up to the checksum
    value, even bytes shifted left by 8."""
    total = 0
    for i, b in enumerate(packet[:-2]):
        total += b << (8 * ((i + 1) % 2))
    return total & 0xFFFF


# -- published values -----------------------------------------------------------------------------


def test_st0902_example_packet_decodes_to_the_published_values():
    """MISB ST 0902 / ST 0601 example packet (DynamicOnlyMISMMSPacketData.bin): values as the
    standard prints them, within one LSB of each tag's mapping."""
    s = read_klv(KLVS / "DynamicOnlyMISMMSPacketData.bin")
    assert s.n_good == 1 and s.issues == []
    c = klv_telemetry(s).columns
    lsb16 = 360 / 65535
    expect = {  # column: (published value, tolerance)
        "yaw_deg": (159.9744, lsb16), "pitch_deg": (-0.4315251, 40 / 65534), "roll_deg": (3.405814, 100 / 65534),
        "lat_deg": (60.1768229669783, 1e-7), "lon_deg": (128.426759042045, 1e-7), "h_msl_m": (14190.72, 0.3),
        "hfov_deg": (144.5713, 180 / 65535), "vfov_deg": (152.6436, 180 / 65535),
        "gimbal1_deg": (160.7192114, 1e-6), "gimbal2_deg": (-168.7923, 5e-5),  # printed to 4 decimals
        "range_m": (68590.98, 0.01), "fc_lat_deg": (-10.5423886331461, 1e-7), "fc_lon_deg": (29.157890122923, 1e-7),
        "fc_h_msl_m": (3216.037, 0.3),
    }
    for col, (value, tol) in expect.items():
        assert abs(c[col][0] - value) <= tol, (col, c[col][0], value)
    assert datetime.fromtimestamp(c["time_s"][0], UTC) == datetime(2009, 1, 12, 22, 8, 22, tzinfo=UTC)
    # MSL -> ellipsoid through the geoid: h = H + N(lat, lon)
    n = default_geoid().undulation(c["lat_deg"][0], c["lon_deg"][0])
    assert c["h_m"][0] == pytest.approx(c["h_msl_m"][0] + n, abs=1e-9)


def test_bad_checksum_is_counted_and_the_packet_not_used():
    """DynamicConstantMISMMSPacketData.bin carries a wrong checksum (SOURCES.md): the reader says so."""
    raw = (KLVS / "DynamicConstantMISMMSPacketData.bin").read_bytes()
    s = decode_klv_bytes(raw, "dc.bin")
    assert s.n_good == 0 and [i.kind for i in s.issues] == ["checksum"]
    assert s.issues[0].offset == 0 and "0xAA43" in s.issues[0].message
    assert _bcc16(raw) != int.from_bytes(raw[-2:], "big")


def test_real_flight_full_range_angles_hae_and_special_values():
    """realflight.bin (ST 0601.11, AR5 UAV on the ground): full-range pitch/roll (tags 90/91) are
    used, HAE tag 75 is taken as is, 'off earth' corners become NaN, every checksum verifies."""
    raw = (KLVS / "realflight.bin").read_bytes()
    packets = _split(raw)
    assert all(_bcc16(p) == int.from_bytes(p[-2:], "big") for p in packets)
    s = read_klv(KLVS / "realflight.bin")
    assert s.n_good == len(packets) == 19 and s.issues == []
    c = klv_telemetry(s).columns
    v0 = s.packets[0].fields
    assert c["pitch_deg"][0] == v0[90] and c["roll_deg"][0] == v0[91]
    assert c["h_m"][0] == v0[75] and np.isnan(c["h_msl_m"][0])
    assert np.isnan(c["corner1_lat_deg"][0]) and np.isfinite(c["corner3_lat_deg"][0])
    assert c["corner3_lat_deg"][0] == v0[86]
    assert np.all(np.diff(c["time_s"]) > 0)


# -- robustness -------------------------------------------------------------------------------------


def test_truncated_packet_does_not_swallow_the_next_one():
    packets = _split((KLVS / "realflight.bin").read_bytes())
    cut = packets[5][: len(packets[5]) // 2]
    data = b"".join(packets[:5]) + cut + b"".join(packets[6:]) + b"\x00garbage"
    s = decode_klv_bytes(data, "cut.bin")
    assert s.n_good == 18
    assert [p.raw for p in s.packets] == packets[:5] + packets[6:]
    kinds = sorted(i.kind for i in s.issues)
    assert kinds == ["checksum", "skipped bytes"] or kinds == ["malformed", "skipped bytes"]
    bad = next(i for i in s.issues if i.packet is not None)
    assert bad.packet == 5 and bad.offset == sum(map(len, packets[:5]))


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.data())
def test_fuzzed_stream_never_crashes_and_keeps_every_untouched_packet(data):
    """One mutation (flip, insert, delete, or a random run of bytes) anywhere in a real stream: no
    exception, every packet the mutation did not touch is kept byte for byte, nothing else is."""
    packets = _split((KLVS / "realflight.bin").read_bytes())
    stream = b"".join(packets)
    pos = data.draw(st.integers(0, len(stream) - 1))
    kind = data.draw(st.sampled_from(["flip", "insert", "delete", "overwrite"]))
    junk = data.draw(st.binary(min_size=1, max_size=40))
    if kind == "flip":
        mutated = stream[:pos] + bytes([stream[pos] ^ data.draw(st.integers(1, 255))]) + stream[pos + 1:]
    elif kind == "insert":
        mutated = stream[:pos] + junk + stream[pos:]
    elif kind == "delete":
        mutated = stream[:pos] + stream[pos + len(junk):]
    else:
        mutated = stream[:pos] + junk + stream[pos + len(junk):]
    s = decode_klv_bytes(mutated, "fuzz.bin")
    bounds = np.cumsum([0] + [len(p) for p in packets])
    span = (pos, pos + (1 if kind == "flip" else len(junk)))
    untouched = [p for k, p in enumerate(packets) if bounds[k + 1] <= span[0] or bounds[k] >= span[1]]
    kept = [p.raw for p in s.packets]
    originals = set(packets)
    assert all(k in originals for k in kept)  # never a packet that was not in the stream
    assert set(untouched) <= set(kept)
    assert s.n_good + s.n_bad >= len(untouched)


@settings(max_examples=60, deadline=None)
@given(st.binary(min_size=0, max_size=600))
def test_random_bytes_after_a_key_never_crash(tail):
    s = decode_klv_bytes(UAS_KEY + tail, "random.bin")
    assert s.n_good + s.n_bad + len(s.issues) >= 1


# -- MPEG-TS ------------------------------------------------------------------------------------------


def _ts_with_pyav(path: Path, packets: list[bytes], fps: int = 10) -> None:
    """An MPEG-TS with one KLV data stream written by libavformat (PyAV): an independent muxer."""
    av = pytest.importorskip("av")
    with av.open(str(path), "w", format="mpegts") as out:
        s = out.add_data_stream(codec_name="klv")
        for i, p in enumerate(packets):
            pkt = av.Packet(p)
            pkt.stream = s
            pkt.pts = pkt.dts = i * 90000 // fps
            pkt.time_base = Fraction(1, 90000)
            out.mux(pkt)


def test_mpegts_from_libavformat_gives_the_same_packets_with_pts(tmp_path):
    packets = _split((KLVS / "realflight.bin").read_bytes())
    ts = tmp_path / "flight.ts"
    _ts_with_pyav(ts, packets)
    s = read_klv(ts)
    assert s.container == "mpegts" and s.n_good == 19 and s.issues == []
    assert [p.raw for p in s.packets] == packets
    assert [p.pts_s for p in s.packets] == pytest.approx([i / 10 for i in range(19)], abs=1e-6)
    raw = klv_telemetry(read_klv(KLVS / "realflight.bin")).columns
    np.testing.assert_array_equal(klv_telemetry(s).columns["yaw_deg"], raw["yaw_deg"])


def test_mpegts_with_a_lost_transport_packet_keeps_the_rest(tmp_path):
    packets = _split((KLVS / "realflight.bin").read_bytes())
    ts = tmp_path / "flight.ts"
    _ts_with_pyav(ts, packets)
    data = ts.read_bytes()
    n = len(data) // 188
    drop = n // 2  # a transport packet in the middle of the stream is lost
    damaged = tmp_path / "damaged.ts"
    damaged.write_bytes(data[:drop * 188] + data[(drop + 1) * 188:])
    s = read_klv(damaged)
    kept = [p.raw for p in s.packets]
    assert set(kept) <= set(packets) and len(kept) >= 17  # at most the KLV packets in that TS packet's PES lost


# -- geometry: the ST 0601 pointing convention, checked against an independent chain -----------------


def _independent_frame_centre(lat, lon, h, heading, pitch, roll, az, el, sroll):
    """LOS from scipy rotations (ZYX platform, then ZYX sensor) and pymap3d's ray-ellipsoid
    intersection at h = 0."""
    R = Rotation.from_euler("ZYX", [heading, pitch, roll], degrees=True) * \
        Rotation.from_euler("ZYX", [az, el, sroll], degrees=True)
    n, e, d = R.apply([1.0, 0.0, 0.0])
    azimuth = np.degrees(np.arctan2(e, n))
    off_nadir = np.degrees(np.arccos(np.clip(d, -1.0, 1.0)))  # pymap3d's tilt: from nadir
    return lookAtSpheroid(lat, lon, h, azimuth, off_nadir)


@settings(max_examples=25, deadline=None)
@given(lat=st.floats(-70, 70), lon=st.floats(-179, 179), h=st.floats(500, 8000), heading=st.floats(0, 359.9),
       pitch=st.floats(-15, 15), roll=st.floats(-30, 30), az=st.floats(0, 359.9), el=st.floats(-80, -25))
def test_frame_centre_matches_an_independent_chain(lat, lon, h, heading, pitch, roll, az, el):
    """Encode a packet, decode it, and place its frame centre with eoloc and with scipy + pymap3d
    from the decoded angles: < 1 cm apart on the ellipsoid (h = 0)."""
    pkt = encode_uas_packet({2: datetime(2026, 1, 1, tzinfo=UTC), 5: heading, 90: pitch, 91: roll, 13: lat, 14: lon,
                             75: h, 16: 10.0, 17: 6.0, 18: az, 19: el, 20: 0.0, 78: 0.0, 23: lat, 24: lon})
    tel = klv_telemetry(decode_klv_bytes(pkt))
    c = tel.columns
    ref_lat, ref_lon, _ = _independent_frame_centre(*(float(c[k][0]) for k in (
        "lat_deg", "lon_deg", "h_m", "yaw_deg", "pitch_deg", "roll_deg", "gimbal1_deg", "gimbal2_deg",
        "sensor_roll_deg")))
    g = frame_geometry(misb_sensor(), packet_pose(tel), c["hfov_deg"], c["vfov_deg"],
                       packet_heights(np.zeros(1)))  # h = 0 exactly
    if np.isnan(ref_lat):  # above the horizon (a roll can lift a -25 deg turret over it): both say so
        assert g.centre.status[0] == eoloc.Status.NO_INTERSECTION
        return
    d = horizontal_distance_m(g.centre.lat_deg[0], g.centre.lon_deg[0], ref_lat, ref_lon)
    assert d < 0.01


def test_offset_corners_and_report_on_change():
    """Corners sent as offsets (26-33) become absolute; a packet that leaves tags out keeps the
    previous values (ST 0601 report on change)."""
    base = {2: datetime(2026, 1, 1, tzinfo=UTC), 5: 10.0, 6: 1.0, 7: 2.0, 13: 40.0, 14: -105.0, 15: 3000.0,
            16: 5.0, 17: 3.0, 18: 90.0, 19: -30.0, 20: 0.0, 23: 40.01, 24: -104.99, 25: 1500.0,
            26: 0.001, 27: -0.002, 28: 0.001, 29: 0.002, 30: -0.001, 31: 0.002, 32: -0.001, 33: -0.002}
    second = {2: datetime(2026, 1, 1, 0, 0, 1, tzinfo=UTC), 13: 40.001}
    s = decode_klv_bytes(encode_uas_packet(base) + encode_uas_packet(second))
    c = klv_telemetry(s).columns
    assert c["corner1_lat_deg"][0] == pytest.approx(40.011, abs=1e-6)
    assert c["corner1_lon_deg"][0] == pytest.approx(-104.992, abs=1e-6)
    assert c["yaw_deg"][1] == c["yaw_deg"][0] and c["fc_lat_deg"][1] == c["fc_lat_deg"][0]
    assert c["lat_deg"][1] == pytest.approx(40.001, abs=1e-7)
    raw = klv_telemetry(s, report_on_change=False).columns
    assert np.isnan(raw["yaw_deg"][1])


# -- VMTI -------------------------------------------------------------------------------------------------


def test_vmti_targets_locate_back_to_known_points():
    """Known ground points (on the ellipsoid at 1 500 m) seen at integer pixels of a 1280 x 720
    image; encoded as ST 0903 targets in ST 0601 packets, read back and located where the
    transmitted (quantised) pose, FOV and height put them: < 1 cm, and on the surface."""
    W, H, hfov, vfov = 1280, 720, 8.0, 4.5
    pixels = np.array([[100, 50], [640, 360], [1200, 700], [333, 444]], dtype=float)
    stream = b""
    truth = []
    for k in range(3):
        pose = Pose(39.5 + 0.001 * k, -104.8, 4500.0, 30.0 + k, 2.0, -1.0, (250.0, -40.0, 0.0))
        values = {2: datetime(2026, 1, 1, 0, 0, k, tzinfo=UTC), 5: float(pose.yaw_deg), 90: 2.0, 91: -1.0,
                  13: float(pose.lat_deg), 14: float(pose.lon_deg), 75: 4500.0, 16: hfov, 17: vfov, 18: 250.0,
                  19: -40.0, 20: 0.0, 78: 1500.0}
        pkt = encode_uas_packet(values)
        dec = klv_telemetry(decode_klv_bytes(pkt)).columns  # truth from the angles as transmitted
        pose_t = Pose(dec["lat_deg"][0], dec["lon_deg"][0], dec["h_m"][0], dec["yaw_deg"][0], dec["pitch_deg"][0],
                      dec["roll_deg"][0], (dec["gimbal1_deg"][0], dec["gimbal2_deg"][0], 0.0))
        from eoloc.rules import locate_ellipsoid

        cam_t = Camera.from_hfov(dec["hfov_deg"][0], W, H, vfov_deg=dec["vfov_deg"][0])  # the FOV as transmitted
        f = locate_ellipsoid(SensorModel(cam_t), pose_t, dec["fc_h_m"][0], (pixels[:, 0], pixels[:, 1]))
        truth.append(np.column_stack([f.lat_deg, f.lon_deg]))
        values[74] = encode_vmti([(j + 1, u, v) for j, (u, v) in enumerate(pixels)], W, H)
        stream += encode_uas_packet(values)
    s = decode_klv_bytes(stream)
    tel, det = klv_telemetry(s), vmti_detections(s)
    assert len(det) == 12
    np.testing.assert_array_equal(det.columns["u_px"][:4], pixels[:, 0])
    np.testing.assert_array_equal(det.columns["v_px"][:4], pixels[:, 1])
    v = locate_vmti(tel, det)
    assert v.fixes.ok.all()
    t = np.vstack(truth)
    d = horizontal_distance_m(v.fixes.lat_deg, v.fixes.lon_deg, t[:, 0], t[:, 1])
    assert d.max() < 0.01, d
    np.testing.assert_allclose(v.fixes.h_m, tel.columns["fc_h_m"][0], atol=1e-3)
    assert abs(tel.columns["fc_h_m"][0] - 1500.0) < 0.2  # tag 78's 2-byte mapping


def test_no_klv_in_file_is_a_clear_error(tmp_path):
    from eoloc.errors import KLVError

    p = tmp_path / "x.klv"
    p.write_bytes(b"")
    with pytest.raises(KLVError, match="empty"):
        read_klv(p)
    with pytest.raises(KLVError, match="cannot read"):
        read_klv(tmp_path / "missing.klv")
    p.write_bytes(os.urandom(5000).replace(UAS_KEY[:4], b"xxxx"))
    with pytest.raises(KLVError, match="no MISB ST 0601 packet"):
        read_klv(p)
