"""`eoloc serve` under load (the real server in its own process, one uvicorn worker, on loopback):

- single-observation requests ([S13]'s reference observation, 1 pixel) sent at a steady 500 req/s
  on one keep-alive connection for ``--seconds``: latency p50/p99 seen by the client (goal p99 <= 10 ms);
- one request of 10^5 pixels (the request limit) over the mountain DEM: targets per second end to
  end, JSON both ways included (goal >= 2 M targets/s);
- the same 10^5 pixels as Arrow columns (``POST /v1/locate/arrow``, an Arrow IPC stream each way,
  the client's encoding and decoding included, through the standard library's http.client), on
  the DEM and at a target height (M3).

Baseline in the same run: the same work through the library in this process (no HTTP, no JSON).

    python bench/bench_serve.py [--seconds 20]
"""

from __future__ import annotations

import http.client
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from _common import best_time, row, script

RATE = 500.0
S13 = {"pose": {"lat_deg": 42.0, "lon_deg": 125.0, "h_m": 10_000.0, "yaw_deg": 10.0, "pitch_deg": 5.0,
                "roll_deg": -2.0, "gimbal_deg": [45.0, -75.0]}, "gimbal": "az-el", "stop": {"range_m": 10_200.0},
       "camera": {"width": 1, "height": 1, "fx": 1.0}}


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def main(seconds: float) -> list[str]:
    import httpx
    import pyarrow as pa

    import eoloc
    from eoloc.io.config import load_config
    from eoloc.rules import OnDEM
    from eoloc.sensor import Pose
    from eoloc.terrain import open_dem

    mountain = Path(eoloc.__file__).parent / "data" / "demo" / "mountain"
    port = _free_port()
    proc = subprocess.Popen([str(Path(sys.executable).parent / "eoloc"), "serve", "--port", str(port), "--config",
                             str(mountain / "camera.toml"), "--dem", f"mountain={mountain / 'longs_peak_srtmgl3.tif'}",
                             "--max-body-mb", "16"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    url = f"http://127.0.0.1:{port}"
    try:
        with httpx.Client(base_url=url, timeout=30) as client:
            for _ in range(300):
                try:
                    client.get("/v1/health")
                    break
                except httpx.TransportError:
                    time.sleep(0.1)
            for _ in range(200):  # warm: imports, compiled kernels, connection
                client.post("/v1/locate", json=S13)
            n = int(seconds * RATE)
            lat = np.empty(n)
            t0 = time.perf_counter()
            for k in range(n):
                due = t0 + k / RATE
                while (wait := due - time.perf_counter()) > 0:
                    time.sleep(min(wait, 0.001))
                a = time.perf_counter()
                r = client.post("/v1/locate", json=S13)
                lat[k] = time.perf_counter() - a
                assert r.status_code == 200 and r.json()["fixes"][0]["status"] == "OK"
            rate = n / (time.perf_counter() - t0)
            # one request of 10^5 pixels over the DEM
            cfg = load_config(mountain / "camera.toml")
            rng = np.random.default_rng(1)
            px = np.column_stack([rng.uniform(0, cfg.camera.width - 1, 100_000),
                                  rng.uniform(0, cfg.camera.height - 1, 100_000)])
            pose = {"lat_deg": 40.255, "lon_deg": -105.625, "h_m": 7000.0, "yaw_deg": 250.0, "pitch_deg": 0.0,
                    "roll_deg": 0.0, "gimbal_deg": [0.0, -90.0]}
            body = {"pose": pose, "pixels": px.tolist(), "stop": {"dem": "mountain"}}

            def batch():
                r = client.post("/v1/locate", json=body)
                assert r.status_code == 200
                return r.json()

            fixes = batch()["fixes"]
            t_http = best_time(batch, repeat=3)
            obs_dem = {"pose": pose, "stop": {"dem": "mountain"}}
            obs_h = {"pose": pose, "stop": {"target_height_m": 3500.0}}

            # the Arrow batches through the standard library's client (http.client, as requests and
            # urllib3 use it): it reads a body in one call, where httpx's pure-Python parser spends
            # 5-8 ms of its own on 5 MB
            plain = http.client.HTTPConnection("127.0.0.1", port, timeout=30)

            def arrow(obs):
                plain.request("POST", "/v1/locate/arrow", body=arrow_body(obs, px),
                              headers={"content-type": "application/vnd.apache.arrow.stream"})
                r = plain.getresponse()
                data = r.read()
                assert r.status == 200, data[:500]
                return pa.ipc.open_stream(data).read_all()

            table = arrow(obs_dem)
            assert table.column("status").to_pylist() == [f["status"] for f in fixes]
            t_arrow = best_time(lambda: arrow(obs_dem), repeat=5)
            ok_h = arrow(obs_h).column("status").to_pylist().count("OK")
            t_arrow_h = best_time(lambda: arrow(obs_h), repeat=5)
    finally:
        proc.terminate()
        proc.wait(10)
    sensor = cfg.sensor()
    rule = OnDEM(open_dem(mountain / "longs_peak_srtmgl3.tif"))
    p = Pose(**{k: v for k, v in pose.items() if k != "gimbal_deg"}, gimbal_deg=tuple(pose["gimbal_deg"]))
    t_lib = best_time(lambda: rule.locate(sensor, p, (px[:, 0], px[:, 1])), repeat=3)
    t_lib_h = best_time(lambda: eoloc.rules.AtHeight(3500.0).locate(sensor, p, (px[:, 0], px[:, 1])), repeat=5)
    lib_one = best_time(lambda: eoloc.rules.AtRange(10_200.0).locate(
        eoloc.SensorModel(eoloc.Camera(1, 1, 1.0, 1.0, 0.0, 0.0), eoloc.AzElGimbal()),
        Pose(42.0, 125.0, 10_000.0, 10.0, 5.0, -2.0, (45.0, -75.0))), repeat=5, number=200)
    ok = sum(f["status"] == "OK" for f in fixes)
    return [
        row(f"`eoloc serve`, single observations at {rate:.0f} req/s for {seconds:.0f} s (one keep-alive "
            f"connection, {n:,} requests)",
            f"p50 {np.percentile(lat, 50) * 1e3:.2f} ms, p99 {np.percentile(lat, 99) * 1e3:.2f} ms, max "
            f"{lat.max() * 1e3:.1f} ms (goal p99 <= 10 ms)", f"library call {lib_one * 1e3:.3f} ms",
            lib_one / np.percentile(lat, 50)),
        row(f"`eoloc serve`, one request of 10^5 pixels over the DEM ({ok:,} OK), JSON both ways",
            f"{1e5 / t_http / 1e6:.2f} M targets/s ({t_http * 1e3:.0f} ms; goal >= 2 M/s)",
            f"library call {t_lib * 1e3:.0f} ms ({1e5 / t_lib / 1e6:.2f} M/s)", t_lib / t_http),
        row("`eoloc serve`, the same 10^5 pixels over the DEM as Arrow columns (`/v1/locate/arrow`, Arrow IPC "
            "both ways)", f"{1e5 / t_arrow / 1e6:.2f} M targets/s ({t_arrow * 1e3:.0f} ms; goal >= 2 M/s)",
            f"library call {t_lib * 1e3:.0f} ms ({1e5 / t_lib / 1e6:.2f} M/s)", t_lib / t_arrow),
        row(f"`eoloc serve`, 10^5 pixels at a target height (M3, {ok_h:,} OK) as Arrow columns",
            f"{1e5 / t_arrow_h / 1e6:.2f} M targets/s ({t_arrow_h * 1e3:.1f} ms; goal >= 2 M/s)",
            f"library call {t_lib_h * 1e3:.1f} ms ({1e5 / t_lib_h / 1e6:.1f} M/s)", t_lib_h / t_arrow_h),
    ]


def arrow_body(obs: dict, px: np.ndarray) -> bytes:
    """An Arrow IPC stream of the pixels, the observation's JSON in the schema metadata."""
    import json

    import pyarrow as pa

    table = pa.table({"u_px": px[:, 0], "v_px": px[:, 1]}).replace_schema_metadata({"eoloc": json.dumps(obs)})
    sink = pa.BufferOutputStream()
    with pa.ipc.new_stream(sink, table.schema) as w:
        w.write_table(table)
    return sink.getvalue().to_pybytes()


if __name__ == "__main__":
    script(main, __doc__, flag="--seconds", kind=float, default=20.0, help_text="length of the 500 req/s run")
