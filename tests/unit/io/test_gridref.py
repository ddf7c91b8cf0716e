"""MGRS (eoloc.io.gridref) against GeographicLib's GeoConvert (Debian geographiclib-tools): the
1 m grid reference truncates, as the standard and GeoConvert do (issue 49; the io package's own
test for issue 55)."""

from __future__ import annotations

import shutil
import subprocess

import numpy as np


def _geoconvert_mgrs(lat: np.ndarray, lon: np.ndarray) -> list[str]:
    """GeographicLib's GeoConvert -m -p 0 (1 m MGRS) on every point, one process."""
    exe = shutil.which("GeoConvert")
    assert exe, "GeoConvert (Debian geographiclib-tools) is installed by `make test` (target geoconvert)"
    text = "\n".join(f"{a:.12f} {b:.12f}" for a, b in zip(lat, lon, strict=True))
    out = subprocess.run([exe, "-m", "-p", "0"], input=text, capture_output=True, text=True, check=True).stdout
    return out.split()


def test_49_9_mgrs_truncates_to_the_metre_as_geoconvert_does():
    """eoloc's MGRS = GeographicLib's GeoConvert over 2.5·10^4 points: random everywhere UTM
    applies, 8 000 within 0.1 mm of a 1 m easting or northing line (where rounding, as the mgrs
    package did, is 1 m off), zone and band edges, Norway's and Svalbard's exceptions."""
    from pyproj import Transformer

    from eoloc.io.gridref import mgrs_column

    rng = np.random.default_rng(49)
    lat = [rng.uniform(-79.99, 83.99, 12_000)]
    lon = [rng.uniform(-180, 180, 12_000)]
    # within 0.1 mm of a metre line: UTM coordinates chosen there, taken back to lat/lon (PROJ)
    for zone in rng.integers(1, 61, 40):
        to_ll = Transformer.from_crs(f"EPSG:{32600 + int(zone)}", "EPSG:4326", always_xy=True)
        e = rng.integers(200_000, 800_000, 200) + rng.choice([-1e-4, 1e-4], 200)
        nn = rng.integers(100_000, 9_000_000, 200) + rng.choice([-1e-4, 1e-4], 200)
        x, y = to_ll.transform(e, nn)
        lat.append(np.asarray(y))
        lon.append(np.asarray(x))
    # zone and band edges, the Norway and Svalbard exceptions
    edge_lon = np.r_[np.arange(-174, 180, 6), 3, 9, 12, 21, 33, 42]
    for d in (-1e-7, 1e-7):
        lon.append(np.tile(edge_lon + d, 20))
        lat.append(np.repeat(np.linspace(-79, 83.5, 20), edge_lon.size))
    bands = np.r_[np.arange(-72, 80, 8), 56, 64, 72]
    for d in (-1e-7, 1e-7):
        lat.append(np.tile(bands + d, 40))
        lon.append(np.repeat(np.linspace(-179, 179, 40), bands.size))
    lat.append(rng.uniform(56, 64, 500))
    lon.append(rng.uniform(0, 12, 500))
    lat.append(rng.uniform(72, 83.99, 500))
    lon.append(rng.uniform(0, 42, 500))
    lat, lon = np.concatenate(lat), np.concatenate(lon)
    assert lat.size >= 20_000
    ours = mgrs_column(lat, lon)
    ref = _geoconvert_mgrs(lat, lon)
    wrong = [(a, b, o, r) for a, b, o, r in zip(lat, lon, ours, ref, strict=True) if o != r]
    assert not wrong, (len(wrong), wrong[:5])
