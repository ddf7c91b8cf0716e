"""The files of the video player page, ``player.html`` beside `eoloc video`'s outputs.

- ``player.html``: the page, self-contained (Leaflet inlined, no network): the video and the map
  side by side; it reads the files below with ``<script>`` and ``<img>``/``<video>`` elements
  only, so it works from a USB stick (``file://``) as well as served by `eoloc serve --player`.
- ``player/video.mp4``: the video as a browser plays it (:func:`eoloc.io.videofile.browser_video`).
- ``player/data.js``: every frame's time, pose and camera, the rectified frames' footprints,
  centres, drapes and grids, the VMTI targets, the mosaic's tiles (:mod:`eoloc.jobs.player`).
- ``player/drape/NNNNNN.webp``: each rectified frame warped to Web Mercator (EPSG:3857, as
  Leaflet draws an image overlay: exact), transparent where the frame did not see the ground.
- ``player/grid/NNNNNN.js``: each rectified frame's ground grid for offline clicks, loaded when
  the page needs it. Points are float32 offsets from a float64 origin (millimetre precision).
"""

from __future__ import annotations

import base64
import json
from pathlib import Path

import numpy as np

DRAPE_MAX_PX = 1024  # a drape's longer side, pixels (the map shows the frame; the COG keeps it all)
DRAPE_QUALITY = 85  # WebP, lossy with an exact alpha


def write_drape(path: str | Path, data: np.ndarray, seen: np.ndarray, transform, crs,
                max_px: int = DRAPE_MAX_PX) -> list[list[float]] | None:
    """A rectified frame (bands, rows, cols on ``transform``/``crs``) warped into Web Mercator as
    a WebP with alpha (``seen``); its [[south, west], [north, east]] bounds, or None (and no file)
    when it saw nothing."""
    import cv2
    from rasterio.warp import Resampling, calculate_default_transform, reproject, transform_bounds

    from .tiles import rasterio_crs, rgba

    if not seen.any():
        return None
    crs = rasterio_crs(crs)
    rows, cols = seen.shape
    x0, y1 = transform.c, transform.f
    x1, y0 = x0 + cols * transform.a, y1 + rows * transform.e
    dst_t, w, h = calculate_default_transform(crs, "EPSG:3857", cols, rows, x0, y0, x1, y1)
    scale = max(w, h) / max_px
    if scale > 1:
        from rasterio.transform import Affine

        dst_t = dst_t @ Affine.scale(scale)
        w, h = max(1, round(w / scale)), max(1, round(h / scale))
    src = rgba(data, seen)
    dst = np.zeros((4, h, w), np.uint8)
    reproject(src, dst, src_transform=transform, src_crs=crs, dst_transform=dst_t, dst_crs="EPSG:3857",
              resampling=Resampling.average if scale > 1 else Resampling.bilinear, src_alpha=4, dst_alpha=4)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    ok, webp = cv2.imencode(".webp", np.moveaxis(dst[[2, 1, 0, 3]], 0, -1), [cv2.IMWRITE_WEBP_QUALITY, DRAPE_QUALITY])
    if not ok:
        raise OSError(f"{path}: WebP encoding failed")
    path.write_bytes(webp.tobytes())
    left, top = dst_t.c, dst_t.f
    right, bottom = left + w * dst_t.a, top + h * dst_t.e
    west, south, east, north = transform_bounds("EPSG:3857", "EPSG:4326", left, bottom, right, top)
    return [[south, west], [north, east]]


def _b64(a: np.ndarray) -> str:
    return base64.b64encode(np.ascontiguousarray(a, dtype="<f4").tobytes()).decode()


def write_grid_script(path: str | Path, index: int, grid) -> Path:
    """A frame's ground grid (:class:`eoloc.jobs.player.OfflineGrid`) as a script that hands it to
    the page: ``eolocGrid(index, {...})``; float32 arrays in base64, row-major."""
    ok = np.isfinite(grid.lat_deg)
    lat0 = float(np.nanmean(grid.lat_deg)) if ok.any() else 0.0
    lon0 = float(np.nanmean(grid.lon_deg)) if ok.any() else 0.0
    body = {"u": grid.u_px.tolist(), "v": grid.v_px.tolist(), "lat0": lat0, "lon0": lon0,
            "dlat": _b64(grid.lat_deg - lat0), "dlon": _b64(grid.lon_deg - lon0), "h": _b64(grid.h_m),
            "cell": _b64(grid.cell_error_m), "px_m": _b64(grid.cell_px_m)}
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(f"eolocGrid({int(index)}, {json.dumps(body)});\n", encoding="utf-8")
    return path


def player_page(title: str) -> str:
    """player.html: the page with Leaflet and the player's script inlined."""
    from .mapview import offline_page

    return offline_page("player/player.html", {"/*PLAYER_JS*/": "player/player.js"}, {"TITLE": title})


def write_player(out: str | Path, data: dict) -> list[Path]:
    """player.html and player/data.js into ``out`` (the video, drapes and grids are written by the
    job as it goes)."""
    out = Path(out)
    (out / "player").mkdir(parents=True, exist_ok=True)
    js = out / "player" / "data.js"
    js.write_text("window.EOLOC_PLAYER = " + json.dumps(data, allow_nan=False, separators=(",", ":")) + ";\n",
                  encoding="utf-8")
    page = out / "player.html"
    page.write_text(player_page(data.get("title", "eoloc player")), encoding="utf-8")
    return [page, js]
