"""DEM sources through rasterio: formats, bilinear heights, voids, tiles, the geoid, errors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import rasterio
from rasterio.transform import from_origin
from scipy.interpolate import RegularGridInterpolator
from where import DATA

from eoloc.terrain import DEM, DEMError, default_geoid, open_dem

DEMS = DATA / "dem"
SRTM = DEMS / "srtm_ref.tif"
DTED = DEMS / "n00_e006_3arc_v2.dt1"
HGT = DEMS / "N10W110.hgt.zip"
ASC = DEMS / "SRTMGL3_boulder_front_range.asc"


def _raw(path, **kw):
    """Orthometric posts and their coordinates straight from rasterio (the independent reading)."""
    with rasterio.open(path) as ds:
        z = ds.read(1, masked=True).astype(float).filled(np.nan)
        t = ds.transform
    lats = t.f + (np.arange(z.shape[0]) + 0.5) * t.e
    lons = t.c + (np.arange(z.shape[1]) + 0.5) * t.a
    return z, lats, lons


def test_geoid_against_sources_and_scipy():
    g = default_geoid()
    # EGM96's published undulations: about -15.9 m at Cheyenne, -13.4 m in the Front Range, +18.6 m at Sao Tome
    assert g.undulation(41.09, -104.85) == pytest.approx(-15.9, abs=0.4)
    assert g.undulation(40.15, -105.5) == pytest.approx(-13.4, abs=0.4)
    assert g.undulation(0.27, 6.54) == pytest.approx(18.6, abs=0.4)
    z, lats, lons = _raw(Path(g.path))
    ref = RegularGridInterpolator((lats[::-1], lons), z[::-1])
    rng = np.random.default_rng(0)
    pts = np.c_[rng.uniform(-89.9, 89.9, 2000), rng.uniform(-180, 179.7, 2000)]
    np.testing.assert_allclose(g.undulation(pts[:, 0], pts[:, 1]), ref(pts), atol=1e-9)
    # longitude wraps: +180 and -180 are the same meridian, 179.9 sits between the last post and -180
    assert g.undulation(10.0, 180.0) == pytest.approx(g.undulation(10.0, -180.0), abs=1e-12)
    assert np.isfinite(g.undulation(10.0, 179.9))


@pytest.mark.parametrize("path, kw, shape, voids", [
    (SRTM, {}, (1000, 1000), 0),
    (DTED, {}, (1201, 1201), 4072),
    (HGT, {}, (1201, 1201), 0),
    (ASC, {"assume_crs": "EPSG:4326"}, (758, 758), 0),
])
def test_formats_open_with_geoid_applied(path, kw, shape, voids):
    dem = open_dem(path, **kw)
    assert dem.grid.shape == shape and dem.n_voids == voids
    gdal_path = f"/vsizip/{path}/N10W110.hgt" if path.suffix == ".zip" else path
    z, lats, lons = _raw(gdal_path)
    rng = np.random.default_rng(1)
    i, j = rng.integers(0, shape[0], 300), rng.integers(0, shape[1], 300)
    expected = z[i, j] + default_geoid().undulation(lats[i], lons[j])
    np.testing.assert_allclose(dem.height(lats[i], lons[j]), expected, atol=1e-9, equal_nan=True)


def test_bilinear_between_posts_matches_scipy():
    dem = open_dem(SRTM, vertical="ellipsoid")
    z, lats, lons = _raw(SRTM)
    ref = RegularGridInterpolator((lats[::-1], lons), z[::-1])
    rng = np.random.default_rng(2)
    pts = np.c_[rng.uniform(lats.min(), lats.max(), 5000), rng.uniform(lons.min(), lons.max(), 5000)]
    np.testing.assert_allclose(dem.height(pts[:, 0], pts[:, 1]), ref(pts), atol=1e-9)


def test_outside_and_voids_are_told_apart():
    dem = open_dem(DTED)
    void = np.argwhere(np.isnan(dem.grid.z))[0]
    lat, lon = dem.grid.lat0 + void[0] * dem.grid.dlat, dem.grid.lon0 + void[1] * dem.grid.dlon
    h, inside = dem.sample(np.array([lat, 0.5, 5.0]), np.array([lon, 6.5, 6.5]))
    assert np.isnan(h[0]) and inside[0]  # a void
    assert np.isfinite(h[1]) and inside[1]
    assert np.isnan(h[2]) and not inside[2]  # out of coverage


def test_tiles_merge_into_one_surface(tmp_path):
    z, lats, lons = _raw(SRTM)
    with rasterio.open(SRTM) as ds:
        profile, t = ds.profile, ds.transform
        data = ds.read(1)
    halves = []
    for k, cols in enumerate((slice(0, 501), slice(500, 1000))):  # overlapping by one column, like DTED
        p = tmp_path / f"tile{k}.tif"
        prof = dict(profile, width=cols.stop - cols.start, transform=t @ rasterio.Affine.translation(cols.start, 0))
        with rasterio.open(p, "w", **prof) as out:
            out.write(data[:, cols], 1)
        halves.append(p)
    merged = open_dem(halves, vertical="ellipsoid")
    single = open_dem(SRTM, vertical="ellipsoid")
    np.testing.assert_array_equal(merged.grid.z, single.grid.z)


def test_projected_dem_is_resampled_to_lat_lon(tmp_path):
    # a plane tilted 1 % toward the east, in UTM zone 37N, 30 m posts
    x0, y0, n = 500_000.0, 4_400_000.0, 200
    xs = x0 + 30.0 * (np.arange(n) + 0.5)
    z = 1000.0 + 0.01 * (xs - x0)[None, :].repeat(n, 0)
    p = tmp_path / "utm.tif"
    with rasterio.open(p, "w", driver="GTiff", width=n, height=n, count=1, dtype="float64", crs="EPSG:32637",
                       transform=from_origin(x0, y0 + 30 * n, 30.0, 30.0)) as out:
        out.write(z, 1)
    dem = open_dem(p, vertical="ellipsoid")
    from pyproj import Transformer

    to_geo = Transformer.from_crs("EPSG:32637", "EPSG:4326", always_xy=True)
    lon, lat = to_geo.transform(x0 + 3000.0, y0 + 3000.0)
    assert dem.height(lat, lon) == pytest.approx(1030.0, abs=0.05)


def test_errors_name_the_file_and_the_fix(tmp_path):
    with pytest.raises(DEMError, match="does not exist"):
        open_dem(tmp_path / "missing.tif")
    junk = tmp_path / "junk.tif"
    junk.write_bytes(b"this is not a raster")
    with pytest.raises(DEMError, match=r"junk\.tif.*cannot be read"):
        open_dem(junk)
    with pytest.raises(DEMError, match=r"no coordinate reference system.*EPSG:4326"):
        open_dem(ASC)
    with pytest.raises(DEMError, match="EGM2008 geoid grid"):
        open_dem(SRTM, vertical="egm2008")


def test_synthetic_and_constant_terrains():
    dem = DEM.from_function(lambda lat, lon: 100.0 + 1000.0 * (lat - 10.0) + 0 * lon, (20.0, 10.0, 20.1, 10.1), 0.001)
    assert dem.height(10.05, 20.05) == pytest.approx(150.0, abs=1e-9)  # bilinear is exact on a plane
    flat = DEM.constant(321.0)
    assert flat.height(-33.0, 151.0) == 321.0 and flat.height_range == (321.0, 321.0)
