"""`eoloc serve`: the HTTP API through a real uvicorn server on loopback, spoken to over TCP by
httpx. Answers are checked against [S13]'s published target and against the library called
directly; bad requests against the field they name."""

from __future__ import annotations

import json
from pathlib import Path

import httpx
import numpy as np
import pymap3d
import pytest
from served import eoloc_serve

import eoloc
from eoloc.io.config import load_config
from eoloc.result import Status
from eoloc.rules import AtHeight, OnDEM
from eoloc.sensor import Pose
from eoloc.terrain import open_dem

MOUNTAIN = Path(eoloc.__file__).parent / "data" / "demo" / "mountain"
S13_TARGET = (42.02058646, 125.03195512, 419.58)  # [S13] Table 3
S13 = {"pose": {"lat_deg": 42.0, "lon_deg": 125.0, "h_m": 10_000.0, "yaw_deg": 10.0, "pitch_deg": 5.0,
                "roll_deg": -2.0, "gimbal_deg": [45.0, -75.0]}, "gimbal": "az-el", "stop": {"range_m": 10_200.0}}


@pytest.fixture(scope="module")
def server():
    """`eoloc serve` as a user starts it, in its own process, with the mountain camera and DEM."""
    with eoloc_serve("--config", str(MOUNTAIN / "camera.toml"), "--dem",
                     f"mountain={MOUNTAIN / 'longs_peak_srtmgl3.tif'}", "--max-body-mb", "0.5") as url:
        yield url


def test_health_and_the_openapi_docs(server):
    h = httpx.get(server + "/v1/health").json()
    assert h["status"] == "ok" and h["config"] is True and h["dems"] == ["mountain"]
    docs = httpx.get(server + "/docs")
    assert docs.status_code == 200 and "swagger" in docs.text.lower()
    spec = httpx.get(server + "/openapi.json").json()
    assert "/v1/locate" in spec["paths"]


def test_s13_through_the_api_is_the_published_target(server):
    r = httpx.post(server + "/v1/locate", json={**S13, "camera": {"width": 1, "height": 1, "fx": 1.0}})
    assert r.status_code == 200, r.text
    (f,) = r.json()["fixes"]
    assert f["status"] == "OK"
    e, n, _ = pymap3d.geodetic2enu(f["lat_deg"], f["lon_deg"], f["h_m"], *S13_TARGET)
    assert np.hypot(e, n) < 0.01 and abs(f["h_m"] - S13_TARGET[2]) < 0.01


def test_a_batch_on_the_dem_equals_the_library(server):
    cfg = load_config(MOUNTAIN / "camera.toml")
    dem = open_dem(MOUNTAIN / "longs_peak_srtmgl3.tif")
    pose = {"lat_deg": 40.23, "lon_deg": -105.66, "h_m": 6500.0, "yaw_deg": 80.0, "pitch_deg": 1.0,
            "roll_deg": -1.5, "gimbal_deg": [10.0, -35.0]}
    pixels = [[100.0, 80.0], [640.0, 360.0], [1200.0, 700.0], [5000.0, 5.0]]  # the last: outside the image
    body = {"observations": [{"pose": pose, "pixels": pixels, "stop": {"dem": "mountain"}},
                             {"pose": pose, "stop": {"target_height_m": 3000.0}}]}
    r = httpx.post(server + "/v1/locate", json=body)
    assert r.status_code == 200, r.text
    a, b = r.json()["results"]
    p = Pose(**{k: v for k, v in pose.items() if k != "gimbal_deg"}, gimbal_deg=(10.0, -35.0, 0.0))
    ref = OnDEM(dem).locate(cfg.sensor(), p, np.array(pixels))
    for k, fix in enumerate(a["fixes"]):
        assert fix["status"] == Status(int(ref.status[k])).name
        if ref.ok[k]:
            assert abs(fix["lat_deg"] - ref.lat_deg[k]) < 1e-12 and abs(fix["h_m"] - ref.h_m[k]) < 1e-6
    assert a["fixes"][3]["status"] == "OUT_OF_IMAGE" and a["fixes"][3]["lat_deg"] is None
    centre = AtHeight(3000.0).locate(cfg.sensor(), p)
    assert b["fixes"][0]["u_px"] == cfg.sensor().camera.cx
    assert abs(b["fixes"][0]["lon_deg"] - float(centre.lon_deg)) < 1e-12


def test_a_ray_above_the_horizon_has_a_status_and_no_point(server):
    up = {**S13, "pose": {**S13["pose"], "gimbal_deg": [0.0, 30.0]}, "stop": {"target_height_m": 0.0}}
    (f,) = httpx.post(server + "/v1/locate", json=up).json()["fixes"]
    assert f["status"] == "NO_INTERSECTION" and f["lat_deg"] is None and f["h_m"] is None


@pytest.mark.parametrize(("body", "field", "words"), [
    ({**S13, "pose": {**S13["pose"], "lat_deg": 95.0}}, "pose.lat_deg", "less than or equal to 90"),
    ({**S13, "stop": {}}, "stop", "exactly one of range_m, target_height_m or dem"),
    ({**S13, "stop": {"range_m": 10.0, "target_height_m": 0.0}}, "stop", "exactly one"),
    ({**S13, "stop": {"dem": "alps"}}, "stop.dem", "no DEM named 'alps'; this server has: mountain"),
    ({**S13, "pose": {**S13["pose"], "gimbal_deg": [45.0]}}, "pose.gimbal_deg", "needs 2 angles"),
    ({**S13, "gimbal": "roll-pitch"}, "gimbal", "contradicts the server config's 'az-el'"),
    ({**S13, "covariance": True}, "covariance", "[accuracy.budget]"),
    ({"observations": [S13, {**S13, "pixels": [[1.0, "x"]]}]}, "observations.1.pixels.0.1", "valid number"),
    ({**S13, "colour": "red"}, "colour", "Extra inputs are not permitted"),
])
def test_a_bad_request_names_its_field(server, body, field, words):
    r = httpx.post(server + "/v1/locate", json=body)
    assert r.status_code == 422, r.text
    problems = r.json()["problems"]
    assert any(p["field"].endswith(field) and words in p["message"] for p in problems), problems


def test_not_json_and_too_large_bodies(server):
    r = httpx.post(server + "/v1/locate", content=b"{not json", headers={"content-type": "application/json"})
    assert r.status_code == 422 and r.json()["error"] == "invalid request"
    big = {"observations": [S13] * 6000}  # ~ 1 MB: over the server's 0.5 MB
    r = httpx.post(server + "/v1/locate", json=big)
    assert r.status_code == 413 and "over this server's limit" in r.json()["error"]
    assert httpx.get(server + "/v1/health").json()["status"] == "ok"  # and the server goes on


def _arrow_body(obs: dict | None, u, v, **columns) -> bytes:
    import pyarrow as pa

    table = pa.table({"u_px": pa.array(u), "v_px": pa.array(v), **columns})
    if obs is not None:
        import json

        table = table.replace_schema_metadata({"eoloc": json.dumps(obs)})
    sink = pa.BufferOutputStream()
    with pa.ipc.new_stream(sink, table.schema) as w:
        w.write_table(table)
    return sink.getvalue().to_pybytes()


def test_arrow_columns_give_what_the_json_rows_give(server):
    """POST /v1/locate/arrow: pixels as Arrow columns, fixes back as Arrow; the same numbers as the
    JSON route and the library (on the DEM), failed fixes null with their status."""
    import pyarrow as pa

    pose = {"lat_deg": 40.23, "lon_deg": -105.66, "h_m": 6500.0, "yaw_deg": 80.0, "pitch_deg": 1.0,
            "roll_deg": -1.5, "gimbal_deg": [10.0, -35.0]}
    rng = np.random.default_rng(3)
    u, v = rng.uniform(-50, 1330, 2000), rng.uniform(-50, 770, 2000)
    obs = {"pose": pose, "stop": {"dem": "mountain"}}
    r = httpx.post(server + "/v1/locate/arrow", content=_arrow_body(obs, u, v),
                   headers={"content-type": "application/vnd.apache.arrow.stream"})
    assert r.status_code == 200 and r.headers["content-type"] == "application/vnd.apache.arrow.stream", r.text
    t = pa.ipc.open_stream(r.content).read_all()
    js = httpx.post(server + "/v1/locate", json={**obs, "pixels": np.c_[u, v].tolist()}).json()["fixes"]
    assert t.num_rows == len(js) == 2000
    status = t.column("status").to_pylist()
    assert status == [f["status"] for f in js]
    assert 1000 < status.count("OK") < 2000 and "OUT_OF_IMAGE" in status
    for name in ("lat_deg", "lon_deg", "h_m", "range_m", "u_px", "v_px"):
        col = t.column(name).to_pylist()
        assert [c is None for c in col] == [f[name] is None for f in js]
        a = np.array([np.nan if c is None else c for c in col])
        b = np.array([np.nan if f[name] is None else f[name] for f in js])
        assert np.array_equal(a, b, equal_nan=True)
    assert all((c is None) == (s != "OK") for c, s in zip(t.column("lat_deg").to_pylist(), status, strict=True))
    assert t.column_names == ["lat_deg", "lon_deg", "h_m", "range_m", "status", "u_px", "v_px"]
    ok = np.array(status) == "OK"
    lib = OnDEM(open_dem(MOUNTAIN / "longs_peak_srtmgl3.tif")).locate(
        load_config(MOUNTAIN / "camera.toml").sensor(), Pose(**{k: x for k, x in pose.items() if k != "gimbal_deg"},
                                                             gimbal_deg=(10.0, -35.0, 0.0)), (u, v))
    assert np.array_equal(np.ravel(lib.ok), ok)
    lat = np.array(t.column("lat_deg").to_pylist(), dtype=float)
    assert np.max(np.abs(lat[ok] - np.ravel(lib.lat_deg)[ok])) < 1e-12


@pytest.mark.parametrize("make, field, words", [
    (lambda: b"not arrow at all", "(body)", "not an Arrow IPC stream"),
    (lambda: _arrow_body(None, [1.0], [2.0]), "(schema metadata)", "no 'eoloc' key"),
    (lambda: _arrow_body({**S13, "stop": {}}, [1.0], [2.0]), "eoloc.stop", "exactly one"),
    (lambda: _arrow_body({**S13, "pixels": [[1, 2]]}, [1.0], [2.0]), "eoloc.pixels", "u_px and v_px columns"),
    (lambda: _arrow_body(S13, [1.0, np.inf], [2.0, 3.0]), "u_px", "row 1 is inf"),
    (lambda: _arrow_body(S13, [1.0, None], [2.0, 3.0]), "u_px", "1 nulls"),
    (lambda: _arrow_body(S13, ["a"], [2.0]), "u_px", "must be numbers"),
])
def test_a_bad_arrow_request_names_its_field(server, make, field, words):
    r = httpx.post(server + "/v1/locate/arrow", content=make(),
                   headers={"content-type": "application/vnd.apache.arrow.stream"})
    assert r.status_code == 422, r.text
    (p,) = r.json()["problems"]
    assert p["field"] == field and words in p["message"], p


def test_arrow_uncertainty_columns_are_the_json_rows_uncertainty():
    """With "covariance": true the Arrow answer carries the same uncertainty columns as the JSON
    rows (the demo camera's [accuracy.budget]), null where the fix failed."""
    import pyarrow as pa

    from eoloc.service.api import (
        ObservationIn,
        ServiceState,
        arrow_fixes,
        locate_observation,
        read_arrow_request,
        solve_observation,
    )

    state = ServiceState(load_config(Path(eoloc.__file__).parent / "data" / "demo" / "camera.toml"))
    obs = {"pose": {**S13["pose"], "gimbal_deg": [45.0, -20.0]}, "stop": {"target_height_m": 100.0},
           "covariance": True}
    u, v = np.array([0.0, 512.0, 1023.0, 5000.0]), np.array([0.0, 384.0, 767.0, 5.0])
    o, uu, vv = read_arrow_request(_arrow_body(obs, u, v))
    t = pa.ipc.open_stream(arrow_fixes(*solve_observation(o, state, "eoloc", pixels=(uu, vv)))).read_all()
    request = json.dumps({**obs, "pixels": np.c_[u, v].tolist()})  # as the JSON route reads it: strictly
    rows = locate_observation(ObservationIn.model_validate_json(request), state, "")
    names = list(rows["fixes"][0]["uncertainty"])
    assert len(names) >= 4 and t.column_names[7:] == names
    for name in names:
        assert t.column(name).to_pylist() == [f["uncertainty"][name] for f in rows["fixes"]]
    assert t.column("status").to_pylist()[3] == "OUT_OF_IMAGE" and t.column(names[0]).to_pylist()[3] is None
