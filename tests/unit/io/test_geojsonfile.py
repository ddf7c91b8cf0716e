"""The GeoJSON writer of point layers against Python's json module: every feature, its geometry
and properties as the records say (numbers rounded as the CSV writes them), valid JSON however the
values go (NaN, infinity, text with quotes and non-ASCII), and the compiled and reference
renderers byte for byte."""

from __future__ import annotations

import json
import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from eoloc.io import rows
from eoloc.io.geojsonfile import write_fix_geojson
from eoloc.io.records import Coded, Records
from eoloc.result import Status

_STATUSES = np.array([s.name for s in Status], dtype=object)
_text = st.none() | st.text(alphabet=st.sampled_from(list('ab ,"\\\n\té€')), max_size=5)


def _expected(value, name: str, whole: bool):
    """A property as json.loads should give it back."""
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float):
        if not math.isfinite(value):
            return None
        # (2^52 and more: whole already, written as it is; numpy's rounding would scale it first)
        r = value if abs(value) >= 2.0**52 else float(np.round(value, 9 if name.endswith("_deg") else 4))
        return int(r) if whole else r
    return value


@settings(max_examples=80, deadline=None)
@given(data=st.data(), n=st.integers(1, 12), chunk=st.sampled_from([2, 5, 1 << 15]),
       coded=st.booleans(), compiled=st.booleans())
def test_fix_features_read_back_as_the_records_say(tmp_path_factory, data, n, chunk, coded, compiled):
    floats = st.floats(-1e7, 1e7) | st.sampled_from([float("nan"), float("inf"), -float("inf")])
    lat = np.array(data.draw(st.lists(st.floats(-90, 90) | st.just(float("nan")), min_size=n, max_size=n)))
    lon = np.array(data.draw(st.lists(st.floats(-180, 180), min_size=n, max_size=n)))
    h = np.array(data.draw(st.lists(st.floats(-500, 9000), min_size=n, max_size=n)))
    codes = np.array(data.draw(st.lists(st.integers(0, len(_STATUSES) - 1), min_size=n, max_size=n)), dtype=np.int8)
    cols = {"line": np.arange(2, 2 + n), "time_s": np.array(data.draw(st.lists(floats, min_size=n, max_size=n))),
            "frame": np.full(n, 7.0), "target_id": np.array(data.draw(st.lists(_text, min_size=n, max_size=n)),
                                                           dtype=object),
            "ok_flag": np.array(data.draw(st.lists(st.booleans(), min_size=n, max_size=n))),
            "lat_deg": lat, "lon_deg": lon, "h_m": h, "range_m": np.array(data.draw(st.lists(floats, min_size=n,
                                                                                           max_size=n))) * 1e9,
            "status": _STATUSES[codes]}
    recs = Records(cols, {"status": Coded(codes, _STATUSES)} if coded else {})
    rows.USE_COMPILED = compiled
    try:
        path = write_fix_geojson(tmp_path_factory.mktemp("g") / "f.geojson", recs, chunk=chunk)
    finally:
        rows.USE_COMPILED = True
    whole = {k: v.dtype.kind == "f" and all(float(x) == int(x) and abs(x) < 2.0**53  # written as integers
                                            for x in [_expected(y, k, False) for y in v] if x is not None)
             for k, v in cols.items()}
    doc = json.loads(path.read_text(encoding="ascii"))  # ASCII: text escaped, as json.dumps does
    assert doc["type"] == "FeatureCollection" and len(doc["features"]) == n
    for i, f in enumerate(doc["features"]):
        assert f["type"] == "Feature"
        if cols["status"][i] == "OK" and np.isfinite([lat[i], lon[i], h[i]]).all():
            assert f["geometry"] == {"type": "Point", "coordinates": [float(np.round(lon[i], 9)),
                                                                      float(np.round(lat[i], 9)),
                                                                      float(np.round(h[i], 4))]}
        else:
            assert f["geometry"] is None
        assert list(f["properties"]) == [k for k in cols if k not in ("lat_deg", "lon_deg")]
        for k, v in f["properties"].items():
            want = _expected(cols[k][i], k, whole[k])
            assert v == want and type(v) is type(want), k  # 7 is not 7.0, nor True 1


@settings(max_examples=40, deadline=None)
@given(data=st.data(), n=st.integers(0, 9))
def test_compiled_and_reference_geojson_are_the_same_bytes(tmp_path_factory, data, n):
    """Numbers near and past what csvrows writes itself (rounded numbers of 15 digits and more),
    whole columns, text and None: the two renderers write the same file."""
    big = st.floats(-1e12, 1e12) | st.floats(-1e17, 1e17) | st.just(float("nan"))
    cols = {"lat_deg": np.array(data.draw(st.lists(st.floats(-1e7, 1e7), min_size=n, max_size=n))),
            "lon_deg": np.zeros(n), "h_m": np.array(data.draw(st.lists(big, min_size=n, max_size=n))),
            "x_m": np.array(data.draw(st.lists(big, min_size=n, max_size=n))),
            "k": np.round(np.array(data.draw(st.lists(big, min_size=n, max_size=n)))),
            "note": np.array(data.draw(st.lists(_text, min_size=n, max_size=n)), dtype=object),
            "status": np.array(["OK"] * n, dtype=object)}
    tmp = tmp_path_factory.mktemp("same")
    fast = write_fix_geojson(tmp / "fast.geojson", Records(cols), chunk=4).read_bytes()
    rows.USE_COMPILED = False
    try:
        slow = write_fix_geojson(tmp / "slow.geojson", Records(cols), chunk=4).read_bytes()
    finally:
        rows.USE_COMPILED = True
    assert fast == slow
    json.loads(fast)


@settings(max_examples=40, deadline=None)
@given(data=st.data())
def test_reference_renderer_is_the_compiled_one(data):
    """rows.render_reference against eoloc.io.csvrows on random specs of every kind."""
    from eoloc.io import csvrows

    n = data.draw(st.integers(0, 12))
    start = data.draw(st.integers(0, 3))
    m = start + n
    specs = []
    for _ in range(data.draw(st.integers(1, 5))):
        kind = data.draw(st.sampled_from([0, 1, 2, 3]))
        pre, suf = data.draw(st.sampled_from([(b"", b","), (b'"k": ', b", "), (b"[", b"]}\n")]))
        if kind == 0:
            specs.append((0, data.draw(st.binary(max_size=4))))
        elif kind == 1:
            d = data.draw(st.sampled_from([0, 4, 9]))
            xs = data.draw(st.lists(st.floats(-1e5, 1e5) | st.just(float("nan")), min_size=m, max_size=m))
            whole = data.draw(st.booleans())
            v = np.round(np.array(xs, dtype=np.float64)) if whole else np.array(xs, dtype=np.float64)
            specs.append((1, v, d, whole, pre, suf, b"null"))
        elif kind == 2:
            specs.append((2, np.array(data.draw(st.lists(st.integers(-2**63, 2**63 - 1), min_size=m, max_size=m)),
                                      dtype=np.int64), pre, suf))
        else:
            names = data.draw(st.lists(st.binary(max_size=3), min_size=1, max_size=4))
            codes = np.array(data.draw(st.lists(st.integers(0, len(names) - 1), min_size=m, max_size=m)),
                             dtype=np.int32)
            specs.append((3, codes, np.cumsum([0] + [len(x) for x in names], dtype=np.int32), b"".join(names)))
    assert csvrows.render(start, n, tuple(specs)) == rows.render_reference(start, n, specs)
