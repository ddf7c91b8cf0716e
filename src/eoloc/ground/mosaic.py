"""A mosaic of a pass: orthorectified frames pasted into one grid, the finest ground sample wins.

Every frame of a pass is rectified onto a grid of the same CRS and cell size whose cell edges sit
on multiples of the cell size (:func:`eoloc.ground.rectify.output_grid`), so each frame's grid is a window
of one endless global grid at whole-cell offsets and pasting is copying, with no resampling. The
mosaic keeps, per cell, the frame that saw it with the smallest ground sample distance (the
frame's pixel footprint on the ground there, :func:`ground_sample_m`), and records that frame's
index and GSD. Memory grows with the ground covered, not with a bounding box: cells live in
chunks of ``chunk`` × ``chunk`` made when a frame first reaches them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pyproj

from ..errors import InputError
from .rectify import FramePixels, OutputGrid

NO_FRAME = -1


def ground_sample_m(px: FramePixels, grid: OutputGrid) -> np.ndarray:
    """Per cell, the ground sample distance (m per image pixel) of the frame there: the cell size
    over the square root of the image pixels one cell spans (|det| of d(u, v)/d(col, row)), NaN
    where the camera does not see the cell. For a geographic grid the cell size is taken in metres
    at the grid's central latitude."""
    u, v = px.u_px.astype(np.float32), px.v_px.astype(np.float32)
    if min(u.shape) < 2:
        return np.full(u.shape, np.nan, np.float32)
    du_dr, du_dc = np.gradient(u)
    dv_dr, dv_dc = np.gradient(v)
    det = np.abs(du_dc * dv_dr - du_dr * dv_dc)
    rx, ry = cell_size_m(grid)
    with np.errstate(divide="ignore", invalid="ignore"):
        gsd = np.float32(math.sqrt(rx * ry)) / np.sqrt(det)
    gsd[~px.valid | ~np.isfinite(gsd)] = np.nan
    return gsd


def cell_size_m(grid: OutputGrid) -> tuple[float, float]:
    """The grid's cell size in metres (x, y); degrees converted at the grid's central latitude."""
    if not grid.crs.is_geographic:
        return float(grid.res[0]), float(grid.res[1])
    _, lat = grid.centres(grid.shape[0] / 2 - 0.5, 0)
    geod = pyproj.Geod(ellps="WGS84")
    lat = float(lat)
    _, _, dx = geod.inv(0.0, lat, grid.res[0], lat)
    _, _, dy = geod.inv(0.0, lat - grid.res[1] / 2, 0.0, lat + grid.res[1] / 2)
    return float(dx), float(dy)


@dataclass(frozen=True)
class MosaicResult:
    """The mosaic: ``data`` (bands, rows, cols) with ``nodata`` where no frame saw the cell,
    ``frame`` (rows, cols) int32 source frame index (-1: none), ``gsd_m`` float32 (NaN: none),
    on ``grid``."""

    grid: OutputGrid
    data: np.ndarray
    frame: np.ndarray
    gsd_m: np.ndarray
    nodata: float

    @property
    def valid(self) -> np.ndarray:
        return self.frame != NO_FRAME


class Mosaic:
    """Frames pasted into one grid of ``crs`` and ``res`` (cell edges on multiples of res)."""

    def __init__(self, crs: pyproj.CRS, res: tuple[float, float], n_bands: int, dtype, nodata: float = 0,
                 *, chunk: int = 512, max_cells: int = 400_000_000) -> None:
        self.crs, self.res = crs, (float(res[0]), float(res[1]))
        self.n_bands, self.dtype, self.nodata = int(n_bands), np.dtype(dtype), nodata
        self.chunk, self.max_cells = int(chunk), int(max_cells)
        self.chunks: dict[tuple[int, int], tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        self.frames = 0

    def origin(self, grid: OutputGrid) -> tuple[int, int]:
        """Global (row, col) of ``grid``'s top-left cell; refuses a grid that is not a window."""
        if not grid.crs.equals(self.crs) or not np.allclose(grid.res, self.res, rtol=1e-9, atol=0):
            raise ValueError(f"a frame grid in {grid.crs.to_string()} at {grid.res} is not part of the mosaic's "
                             f"{self.crs.to_string()} grid at {self.res}")
        t = grid.transform
        col, row = t.c / self.res[0], -t.f / self.res[1]
        if abs(col - round(col)) > 1e-6 or abs(row - round(row)) > 1e-6:
            raise ValueError("a frame grid whose cell edges are not on multiples of the cell size")
        return round(row), round(col)

    def add(self, frame: int, grid: OutputGrid, data: np.ndarray, valid: np.ndarray, gsd_m: np.ndarray) -> int:
        """Paste ``data`` (bands, rows, cols) of frame ``frame`` where it is valid and finer than
        what the mosaic holds; returns how many cells it won."""
        r0, c0 = self.origin(grid)
        rows, cols = grid.shape
        n = self.chunk
        won = 0
        better_gsd = np.where(valid, gsd_m, np.inf).astype(np.float32)
        better_gsd[~np.isfinite(better_gsd) & valid] = np.float32(3.0e38)  # seen, GSD unknown: weakest claim
        for R in range(r0 // n, (r0 + rows - 1) // n + 1):
            for C in range(c0 // n, (c0 + cols - 1) // n + 1):
                # the overlap of chunk (R, C) with the frame, in both frames of reference
                gr0, gr1 = max(R * n, r0), min((R + 1) * n, r0 + rows)
                gc0, gc1 = max(C * n, c0), min((C + 1) * n, c0 + cols)
                f = (slice(gr0 - r0, gr1 - r0), slice(gc0 - c0, gc1 - c0))
                cand = better_gsd[f]
                if not np.isfinite(cand).any():
                    continue
                ch = self._chunk(R, C)
                k = (slice(gr0 - R * n, gr1 - R * n), slice(gc0 - C * n, gc1 - C * n))
                best = ch[2][k]
                win = cand < np.where(np.isnan(best), np.inf, best)
                if not win.any():
                    continue
                ch[0][(slice(None), *k)][:, win] = data[(slice(None), *f)][:, win]
                ch[1][k][win] = frame
                best[win] = cand[win]
                won += int(win.sum())
        self.frames += 1
        return won

    def _chunk(self, R: int, C: int):
        ch = self.chunks.get((R, C))
        if ch is None:
            if (len(self.chunks) + 1) * self.chunk**2 > self.max_cells:
                raise InputError(f"the mosaic would pass {self.max_cells:,} cells: give a coarser cell size (--gsd) "
                                 "or fewer frames (--every, --start/--end)")
            n = self.chunk
            ch = (np.full((self.n_bands, n, n), self.nodata, self.dtype), np.full((n, n), NO_FRAME, np.int32),
                  np.full((n, n), np.nan, np.float32))
            self.chunks[(R, C)] = ch
        return ch

    def result(self) -> MosaicResult:
        """The mosaic cut to the cells some frame saw."""
        from rasterio.transform import from_origin

        if not self.chunks:
            raise InputError("no frame saw the ground: the mosaic is empty")
        n = self.chunk
        Rs, Cs = [k[0] for k in self.chunks], [k[1] for k in self.chunks]
        R0, C0 = min(Rs), min(Cs)
        rows, cols = (max(Rs) - R0 + 1) * n, (max(Cs) - C0 + 1) * n
        frame = np.full((rows, cols), NO_FRAME, np.int32)
        for (R, C), ch in self.chunks.items():
            frame[(R - R0) * n:(R - R0 + 1) * n, (C - C0) * n:(C - C0 + 1) * n] = ch[1]
        seen_r, seen_c = np.flatnonzero((frame >= 0).any(1)), np.flatnonzero((frame >= 0).any(0))
        if seen_r.size == 0:
            raise InputError("no frame saw the ground: the mosaic is empty")
        ra, rb, ca, cb = seen_r[0], seen_r[-1] + 1, seen_c[0], seen_c[-1] + 1
        data = np.full((self.n_bands, rb - ra, cb - ca), self.nodata, self.dtype)
        gsd = np.full((rb - ra, cb - ca), np.nan, np.float32)
        for (R, C), ch in self.chunks.items():
            gr0, gc0 = (R - R0) * n, (C - C0) * n
            a, b = max(gr0, ra), min(gr0 + n, rb)
            c, d = max(gc0, ca), min(gc0 + n, cb)
            if a >= b or c >= d:
                continue
            data[:, a - ra:b - ra, c - ca:d - ca] = ch[0][:, a - gr0:b - gr0, c - gc0:d - gc0]
            gsd[a - ra:b - ra, c - ca:d - ca] = ch[2][a - gr0:b - gr0, c - gc0:d - gc0]
        gsd[gsd > 1e38] = np.nan  # seen, with no GSD known
        top_row, left_col = R0 * n + ra, C0 * n + ca
        transform = from_origin(left_col * self.res[0], -top_row * self.res[1], self.res[0], self.res[1])
        grid = OutputGrid(self.crs, transform, (int(rb - ra), int(cb - ca)), self.res)
        return MosaicResult(grid, data, frame[ra:rb, ca:cb].copy(), gsd, self.nodata)
