"""M5 orthorectification by forward projection: the compiled passes over the output cells.

Ground -> image, one output cell at a time (README "Orthorectification"):

1. ``project_cells``: a cell's place in the DEM's grid (fractional row and column: linear in
   latitude and longitude), and the camera-frame position of its ellipsoid point and up normal,
   interpolated bilinearly from nodes every ``step`` cells that pyproj and the exact geodesy
   computed (the interpolation error is (step * cell)^2 / 8R: 5 µm at 16 cells of 1 m); the
   DEM's bilinear height there (or the constant surface); the camera
   frame point c0 + h n; its pinhole projection, the lens distortion (the same
   ``core.distort`` as every other ground -> pixel path) and its range; whether it lies in
   the image, with the sampling maps for OpenCV's remap (final wherever nothing hides it). Per
   row, by node interval, so that the node values are constants of loops LLVM vectorises.
2. ``fold_tiles``: terrain hides terrain only where the mesh of the cells (two triangles per
   2 x 2 cells) folds over in the image, i.e. near its back-facing triangles; the image tiles
   they touch are marked. No back face: nothing is hidden and the z-buffer is skipped.
3. ``rasterize_depth``: a z-buffer at the image's resolution, filled in the blocks of cells that
   meet a marked tile: every triangle rasterised at the pixel centres it covers with its
   interpolated range, the nearest kept. A triangulated surface covers its image without gaps,
   so no pixel behind a ridge is left open.
4. ``hide_folded``: in those blocks only, a cell in the image is hidden when its range is more
   than the farthest of the z-buffer's at the four pixel centres around its pixel, plus a slack
   for the mesh's curvature (about one cell's range change, ``range_slack``). A linear surface's
   range at a point inside a square is at most its largest at the corners, so a cell on the
   nearest surface passes, and a cell is hidden only when nearer terrain covers all four: at a
   silhouette the sub-cell doubt goes to "seen".
5. ``sample_bands``: nearest or exact bilinear sampling (uint8/uint16 bilinear goes
   through OpenCV's remap, eoloc.ground.rectify.resample).

Each is plain scalar code that numba compiles (eoloc.kernels.compiled) with the kernels' compiled twins; the
numpy reference is :func:`eoloc.ground.rectify.orthorectify_reference`, which reaches the same cells by
scipy's map_coordinates and decides hiding by each cell's own ray (M4) instead of a z-buffer.
"""

from __future__ import annotations

import numpy as np

from .core import compiled, distort, grid_height_at

N_NODE = 8  # per node: the DEM's fractional row and column there, camera-frame ellipsoid point (x, y, z), up (x, y, z)
BLOCK = 16  # cells per side of the blocks the z-buffer pass takes or skips whole
_TRI_EPS = 1e-9  # barycentric slack: a pixel centre on the edge shared by two triangles goes to both


def node_count(n_cells: int, step: int) -> int:
    """Nodes along an axis of n_cells cells: at cells 0, step, 2 step, ..., the last at or past
    the last cell (at least two)."""
    return max(-(-(n_cells - 1) // step) + 1, 2)


def node_index(n_cells: int, step: int) -> tuple[np.ndarray, np.ndarray]:
    """Per cell along one axis: the node before it and the fraction of the way to the next."""
    k = np.arange(n_cells) / step
    i0 = np.minimum(np.floor(k).astype(np.int64), node_count(n_cells, step) - 2)
    return i0, k - i0


@compiled()
def project_cells(nodes, row_i0, row_a, step, col_a, dem_z, h_const, use_dem, fx, fy, cx, cy, dist_kind,
                  dist_params, r2_max, width, height, u, v, rng, valid, map_x, map_y, fold, tile_px, tiles, boxes):
    """Pass 1: every cell -> pixel (u, v) and range (m); NaN where it has no ground (off the DEM,
    a void) or does not lie in front of the camera within the lens model's field (r2_max: the
    largest squared ideal normalised radius the image reaches). And whether the cell lies in the
    ``width`` x ``height`` image, with the sampling maps OpenCV's remap takes (see
    :func:`seen_maps`): final, unless the z-buffer pass (:func:`hide_folded`) finds the cell
    hidden by nearer terrain. With ``fold``, also
    :func:`fold_tiles` with front = +1, each row of quads as soon as its two rows are done, and
    the image bounding boxes of the z-buffer pass's blocks of cells (``boxes``, see
    :func:`block_boxes`); returns the fold test's (front faces, back faces), (0, 0) without."""
    rows = u.shape[0]
    cols = u.shape[1]
    n_nodes = nodes.shape[1]
    line = np.empty((n_nodes, N_NODE))  # the nodes interpolated to this row
    h_row = np.empty(cols)
    fr_row = np.empty(cols)
    fc_row = np.empty(cols)
    xs = np.empty(cols)  # ideal normalised image coordinates (NaN: no pixel)
    ys = np.empty(cols)
    n_front = 0
    n_back = 0
    area = np.empty((2, cols))  # fold_row's scratch
    for r in range(rows):
        i = row_i0[r]
        a = row_a[r]
        for j in range(n_nodes):
            for k in range(N_NODE):
                line[j, k] = (1.0 - a) * nodes[i, j, k] + a * nodes[i + 1, j, k]
        # by node interval (the nodes' values constant in the inner loops, which LLVM vectorises),
        # the DEM's lookups (gathers) in a loop of their own
        for j in range(n_nodes - 1):
            c0, c1 = node_span(j, step, n_nodes, cols)
            # slices indexed from 0: numba wraps negative indices, so an index counted from c0 (not
            # provably >= 0) made every load a gather and every store a scatter (13.3 -> 9.0 ms a frame)
            ca, fr_s, fc_s = col_a[c0:c1], fr_row[c0:c1], fc_row[c0:c1]
            fr_a, fr_b, fc_a, fc_b = line[j, 0], line[j + 1, 0], line[j, 1], line[j + 1, 1]
            for k in range(c1 - c0):
                b = ca[k]
                fr_s[k] = (1.0 - b) * fr_a + b * fr_b  # the DEM's fractional row
                fc_s[k] = (1.0 - b) * fc_a + b * fc_b  # and column
        if use_dem:
            for c in range(cols):
                h_row[c], inside = grid_height_at(dem_z, fr_row[c], fc_row[c])
        else:
            h_row[:] = h_const
        ur = u[r]
        vr = v[r]
        rr = rng[r]
        for j in range(n_nodes - 1):
            c0, c1 = node_span(j, step, n_nodes, cols)
            pxa, pya, pza, qxa, qya, qza = line[j, 2], line[j, 3], line[j, 4], line[j, 5], line[j, 6], line[j, 7]
            pxb, pyb, pzb, qxb, qyb, qzb = (line[j + 1, 2], line[j + 1, 3], line[j + 1, 4], line[j + 1, 5],
                                            line[j + 1, 6], line[j + 1, 7])
            ca, hs, xs_s, ys_s, rr_s = col_a[c0:c1], h_row[c0:c1], xs[c0:c1], ys[c0:c1], rr[c0:c1]
            for k in range(c1 - c0):
                b = ca[k]
                h = hs[k]
                X = (1.0 - b) * (pxa + h * qxa) + b * (pxb + h * qxb)
                Y = (1.0 - b) * (pya + h * qya) + b * (pyb + h * qyb)
                Z = (1.0 - b) * (pza + h * qza) + b * (pzb + h * qzb)
                xn = X / Z
                yn = Y / Z
                ok = (Z > 0.0) & (xn * xn + yn * yn <= r2_max)  # False for NaN (no ground)
                xs_s[k] = xn if ok else np.nan
                ys_s[k] = yn if ok else np.nan
                rr_s[k] = np.sqrt(X * X + Y * Y + Z * Z) if ok else np.nan
        if dist_kind == 0:
            for c in range(cols):
                ur[c] = fx * xs[c] + cx
                vr[c] = fy * ys[c] + cy
        else:
            for c in range(cols):
                xd, yd = distort(dist_kind, dist_params, xs[c], ys[c])
                ur[c] = fx * xd + cx
                vr[c] = fy * yd + cy
        for c in range(cols):  # a loop of its own, on the row still in cache: it vectorises too
            valid[r, c], map_x[r, c], map_y[r, c] = seen_maps(u[r, c], v[r, c], width, height)
        if fold:
            box_row(u, v, r, boxes)
            if r > 0:
                f, bk = fold_row(u, v, r - 1, tile_px, 1.0, tiles, area)
                n_front += f
                n_back += bk
    return n_front, n_back


@compiled(inline=True)
def node_span(j, step, n_nodes, cols):
    """The cells [c0, c1) between node j and node j + 1 (the last interval takes the rest, as
    :func:`node_index` puts them there)."""
    c0 = j * step
    return c0, (cols if j == n_nodes - 2 else min(c0 + step, cols))


def block_boxes(rows: int, cols: int) -> np.ndarray:
    """The blocks' image bounding boxes to be filled by :func:`project_cells` (umin, umax, vmin,
    vmax per block of BLOCK x BLOCK quads, i.e. BLOCK + 1 cells a side; empty: +inf, -inf)."""
    boxes = np.empty((max(-(-(rows - 1) // BLOCK), 1), max(-(-(cols - 1) // BLOCK), 1), 4))
    boxes[..., 0::2], boxes[..., 1::2] = np.inf, -np.inf
    return boxes


@compiled(inline=True)
def box_row(u, v, r, boxes):
    """Widen the boxes of the blocks that cell row r belongs to (a row on a block boundary belongs
    to the blocks above and below it, as a column does to those left and right)."""
    cols = u.shape[1]
    n_br = boxes.shape[0]
    for bc in range(boxes.shape[1]):
        umin = np.inf
        umax = -np.inf
        vmin = np.inf
        vmax = -np.inf
        c0 = bc * BLOCK
        ub = u[r, c0:min(c0 + BLOCK + 1, cols)]  # indexed from 0: vector loads (see project_cells)
        vb = v[r, c0:min(c0 + BLOCK + 1, cols)]
        for k in range(ub.size):  # branch-free: NaN never wins
            uc = ub[k]
            vc = vb[k]
            umin = uc if uc < umin else umin
            umax = uc if uc > umax else umax
            vmin = vc if vc < vmin else vmin
            vmax = vc if vc > vmax else vmax
        if not umin <= umax:
            continue
        for br in range(r // BLOCK - (1 if r % BLOCK == 0 else 0), r // BLOCK + 1):
            if br >= 0 and br < n_br:
                boxes[br, bc, 0] = min(boxes[br, bc, 0], umin)
                boxes[br, bc, 1] = max(boxes[br, bc, 1], umax)
                boxes[br, bc, 2] = min(boxes[br, bc, 2], vmin)
                boxes[br, bc, 3] = max(boxes[br, bc, 3], vmax)


@compiled(inline=True)
def cover(zbuf, x, y, ua, va, da, ub, vb, db, uc, vc, dc, inv):
    """Keep the nearer of the z-buffer's range at pixel centre (x, y) and triangle abc's there, if
    the triangle covers it (inv: 1 / the triangle's doubled signed area)."""
    wb = ((x - ua) * (vc - va) - (uc - ua) * (y - va)) * inv
    wc = ((ub - ua) * (y - va) - (x - ua) * (vb - va)) * inv
    wa = 1.0 - wb - wc
    if wa >= -_TRI_EPS and wb >= -_TRI_EPS and wc >= -_TRI_EPS:
        z = wa * da + wb * db + wc * dc
        if z < zbuf[y, x]:
            zbuf[y, x] = z


@compiled(inline=True)
def raster_quad(zbuf, u00, v00, d00, u01, v01, d01, u10, v10, d10, u11, v11, d11):
    """Rasterise the two triangles (00, 01, 11) and (00, 11, 10) of a mesh quad into the z-buffer
    (either may be missing: a NaN range) at the pixel centres (integer u, v) they cover."""
    height = zbuf.shape[0]
    width = zbuf.shape[1]
    t1 = (d01 - d01) == 0.0
    t2 = (d10 - d10) == 0.0
    umin = min(u00, u11, u01 if t1 else u00, u10 if t2 else u00)
    umax = max(u00, u11, u01 if t1 else u00, u10 if t2 else u00)
    vmin = min(v00, v11, v01 if t1 else v00, v10 if t2 else v00)
    vmax = max(v00, v11, v01 if t1 else v00, v10 if t2 else v00)
    x0 = max(int(np.ceil(umin)), 0)
    x1 = min(int(np.floor(umax)), width - 1)
    y0 = max(int(np.ceil(vmin)), 0)
    y1 = min(int(np.floor(vmax)), height - 1)
    if x0 > x1 or y0 > y1:  # no pixel centre inside: the common case for cells the size of a pixel
        return
    a1 = (u01 - u00) * (v11 - v00) - (u11 - u00) * (v01 - v00)
    a2 = (u11 - u00) * (v10 - v00) - (u10 - u00) * (v11 - v00)
    t1 = t1 and a1 != 0.0
    t2 = t2 and a2 != 0.0
    inv1 = 1.0 / a1 if t1 else 0.0
    inv2 = 1.0 / a2 if t2 else 0.0
    for y in range(y0, y1 + 1):
        for x in range(x0, x1 + 1):
            if t1:
                cover(zbuf, x, y, u00, v00, d00, u01, v01, d01, u11, v11, d11, inv1)
            if t2:
                cover(zbuf, x, y, u00, v00, d00, u11, v11, d11, u10, v10, d10, inv2)


@compiled(inline=True)
def fold_row(u, v, r, tile_px, front, tiles, area):
    """:func:`fold_tiles` for the quads between cell rows r and r + 1 -> (front faces, back faces);
    ``area``: scratch of (2, columns). A triangle with a vertex that does not project has a NaN
    area (u, v are NaN there) and counts neither way. The areas are taken in one branch-free loop
    (vectorised); the back faces' tiles are marked in a second, only when the row has any."""
    cols = u.shape[1]
    n_ty = tiles.shape[0]
    n_tx = tiles.shape[1]
    n_front = 0
    n_back = 0
    for c in range(cols - 1):
        u00 = u[r, c]
        v00 = v[r, c]
        du = u[r + 1, c + 1] - u00
        dv = v[r + 1, c + 1] - v00
        # (00, 01, 11) and (00, 11, 10): the second walks the other way round, hence its minus
        a1 = front * ((u[r, c + 1] - u00) * dv - du * (v[r, c + 1] - v00))
        a2 = -front * ((u[r + 1, c] - u00) * dv - du * (v[r + 1, c] - v00))
        area[0, c] = a1
        area[1, c] = a2
        n_front += (a1 >= 0.0) + (a2 >= 0.0)
        n_back += (a1 < 0.0) + (a2 < 0.0)
    if n_back == 0:
        return n_front, n_back
    for c in range(cols - 1):
        for t in range(2):
            if not area[t, c] < 0.0:
                continue
            uo = u[r, c + 1] if t == 0 else u[r + 1, c]
            vo = v[r, c + 1] if t == 0 else v[r + 1, c]
            u00 = u[r, c]
            v00 = v[r, c]
            u11 = u[r + 1, c + 1]
            v11 = v[r + 1, c + 1]
            tx0 = max(int(np.floor(min(u00, u11, uo) / tile_px)) - 1, 0)
            tx1 = min(int(np.floor(max(u00, u11, uo) / tile_px)) + 1, n_tx - 1)
            ty0 = max(int(np.floor(min(v00, v11, vo) / tile_px)) - 1, 0)
            ty1 = min(int(np.floor(max(v00, v11, vo) / tile_px)) + 1, n_ty - 1)
            for ty in range(ty0, ty1 + 1):
                for tx in range(tx0, tx1 + 1):
                    tiles[ty, tx] = 1
    return n_front, n_back


@compiled()
def fold_tiles(u, v, tile_px, front, tiles):
    """Mark the image tiles (tile_px square, one tile of margin around) that the mesh's back
    faces touch: triangles whose doubled signed area in the image has the sign opposite to
    ``front`` (+1: counter-clockwise in (u, v) faces the camera), and return (how many face each
    way). The caller checks that the front faces are the majority. (``project_cells`` runs the
    same test with front = +1 as it goes, row by row, while the rows are in cache.)

    Terrain hides terrain only where the mesh folds over in the image: a point of the image that
    several layers of the surface cover is covered by a back-facing triangle too (the layers'
    orientations add up to the image's one), so the z-buffer is needed in the back faces' tiles
    only."""
    n_front = 0
    n_back = 0
    area = np.empty((2, u.shape[1]))
    for r in range(u.shape[0] - 1):
        f, b = fold_row(u, v, r, tile_px, front, tiles, area)
        n_front += f
        n_back += b
    return n_front, n_back


@compiled()
def marked_table(tiles):
    """Summed-area table of the marked tiles: whether a box holds any, in O(1) (:func:`box_marked`)."""
    n_ty = tiles.shape[0]
    n_tx = tiles.shape[1]
    sat = np.zeros((n_ty + 1, n_tx + 1), np.int64)
    for ty in range(n_ty):
        for tx in range(n_tx):
            sat[ty + 1, tx + 1] = sat[ty, tx + 1] + sat[ty + 1, tx] - sat[ty, tx] + tiles[ty, tx]
    return sat


@compiled(inline=True)
def box_marked(boxes, b_r, b_c, tile_px, sat):
    """Whether block (b_r, b_c)'s image box (``boxes``, from :func:`project_cells`) meets a marked
    tile (``sat``: :func:`marked_table`); False for a block with no projected cell."""
    umin = boxes[b_r, b_c, 0]
    umax = boxes[b_r, b_c, 1]
    vmin = boxes[b_r, b_c, 2]
    vmax = boxes[b_r, b_c, 3]
    if not umin <= umax:
        return False
    n_ty = sat.shape[0] - 1
    n_tx = sat.shape[1] - 1
    tx0 = min(max(int(np.floor(umin / tile_px)), 0), n_tx - 1)
    tx1 = min(max(int(np.floor(umax / tile_px)), 0), n_tx - 1)
    ty0 = min(max(int(np.floor(vmin / tile_px)), 0), n_ty - 1)
    ty1 = min(max(int(np.floor(vmax / tile_px)), 0), n_ty - 1)
    return sat[ty1 + 1, tx1 + 1] - sat[ty0, tx1 + 1] - sat[ty1 + 1, tx0] + sat[ty0, tx0] != 0


@compiled()
def rasterize_depth(u, v, rng, tile_px, tiles, boxes, zbuf):
    """Pass 2: the z-buffer (image rows x columns, filled with +inf by the caller), in the marked
    tiles, of the mesh whose vertices are the cells (triangles (r, c) (r, c+1) (r+1, c+1) and
    (r, c) (r+1, c+1) (r+1, c), where all three vertices project). The cells are taken in blocks
    of BLOCK x BLOCK quads; a block whose image bounding box (``boxes``, from project_cells) meets
    no marked tile is skipped."""
    rows = u.shape[0]
    cols = u.shape[1]
    sat = marked_table(tiles)
    for br in range(0, rows - 1, BLOCK):
        for bc in range(0, cols - 1, BLOCK):
            if not box_marked(boxes, br // BLOCK, bc // BLOCK, tile_px, sat):
                continue
            r1 = min(br + BLOCK + 1, rows)
            c1 = min(bc + BLOCK + 1, cols)
            for r in range(br, r1 - 1):
                for c in range(bc, c1 - 1):
                    d00 = rng[r, c]
                    d11 = rng[r + 1, c + 1]
                    if (d00 - d00) == 0.0 and (d11 - d11) == 0.0:
                        raster_quad(zbuf, u[r, c], v[r, c], d00, u[r, c + 1], v[r, c + 1], rng[r, c + 1], u[r + 1, c],
                                    v[r + 1, c], rng[r + 1, c], u[r + 1, c + 1], v[r + 1, c + 1], d11)


@compiled()
def neighbour_difference(x, r, c, dr, dc):
    """x[r + dr, c + dc] - x[r, c] (one-sided at the grid's edge: the other side; NaN if none)."""
    rows = x.shape[0]
    cols = x.shape[1]
    r1 = r + dr
    c1 = c + dc
    if r1 < 0 or r1 >= rows or c1 < 0 or c1 >= cols:
        r1 = r - dr
        c1 = c - dc
        if r1 < 0 or r1 >= rows or c1 < 0 or c1 >= cols:
            return np.nan
        return x[r, c] - x[r1, c1]
    return x[r1, c1] - x[r, c]


@compiled()
def range_slack(u, v, rng, r, c):
    """How much farther than the four pixel centres around its pixel a cell on the nearest
    surface may lie (the mesh's curvature within a pixel): the largest range change to a
    neighbouring cell, times the pixels the cell spans if it is smaller than 1.5 px (NaN where no
    neighbour projects: the caller then gives the cell the benefit of the doubt). Bounded by the
    cells' own spacing, not by a range gradient: at a fold of the image, where the gradient is
    unbounded, it would excuse any hidden cell."""
    step = np.nan
    size = 0.0
    for k in range(4):
        dr = 1 if k == 0 else (-1 if k == 1 else 0)
        dc = 1 if k == 2 else (-1 if k == 3 else 0)
        dd = neighbour_difference(rng, r, c, dr, dc)
        du = neighbour_difference(u, r, c, dr, dc)
        dv = neighbour_difference(v, r, c, dr, dc)
        if (dd - dd) == 0.0:
            step = abs(dd) if not (step >= abs(dd)) else step
            size = max(size, np.sqrt(du * du + dv * dv))
    return step * max(1.0, 1.5 / size) if size > 0.0 else step


@compiled(inline=True)
def seen_maps(uc, vc, width, height):
    """(1 if pixel (uc, vc) lies in the image — within the outer edges of the edge pixels — else
    0, and the sampling maps OpenCV's remap takes (float32): the pixel, clamped to the outermost
    pixel centres (a read past them takes the edge pixel), or -16 (outside: nodata))."""
    seen = uc >= -0.5 and uc <= width - 0.5 and vc >= -0.5 and vc <= height - 0.5
    return (1 if seen else 0), (min(max(uc, 0.0), width - 1.0) if seen else -16.0), \
        (min(max(vc, 0.0), height - 1.0) if seen else -16.0)


@compiled()
def hide_folded(u, v, rng, zbuf, tile_px, tiles, boxes, width, height, valid, map_x, map_y):
    """Pass 3: the cells nearer terrain hides, taken out of ``valid`` and the maps: a cell whose
    range is beyond the z-buffer's at the four pixel centres around its pixel (by more than the
    mesh's own curvature there, :func:`range_slack`). Only the blocks of cells whose image box
    (``boxes``) meets a marked tile are visited: elsewhere the mesh does not fold over, so nothing
    there is hidden (:func:`fold_tiles`)."""
    rows = u.shape[0]
    cols = u.shape[1]
    sat = marked_table(tiles)
    for br in range(0, rows, BLOCK):
        for bc in range(0, cols, BLOCK):
            # (the last row or column of cells belongs to the last block)
            if not box_marked(boxes, min(br // BLOCK, boxes.shape[0] - 1), min(bc // BLOCK, boxes.shape[1] - 1),
                              tile_px, sat):
                continue
            for r in range(br, min(br + BLOCK, rows)):
                for c in range(bc, min(bc + BLOCK, cols)):
                    if valid[r, c] == 0:
                        continue
                    uc = u[r, c]
                    vc = v[r, c]
                    x0 = min(max(int(np.floor(uc)), 0), width - 1)
                    y0 = min(max(int(np.floor(vc)), 0), height - 1)
                    x1 = min(x0 + 1, width - 1)
                    y1 = min(y0 + 1, height - 1)
                    z = max(zbuf[y0, x0], zbuf[y0, x1], zbuf[y1, x0], zbuf[y1, x1])
                    d = rng[r, c]
                    if d > z:
                        slack = range_slack(u, v, rng, r, c)
                        if d > z + slack + 1e-4 * d + 0.01:  # NaN slack: seen
                            valid[r, c] = 0
                            map_x[r, c] = -16.0
                            map_y[r, c] = -16.0


@compiled()
def sample_bands(image, u, v, valid, bilinear, is_int, nodata, out):
    """Pass 4: out[b, r, c] = image band b at (u, v) (bilinear, or nearest) where valid, else
    nodata; integer outputs rounded. Pixel centres at integers; reads past
    the last centre take the edge pixel's value."""
    bands = image.shape[0]
    height = image.shape[1]
    width = image.shape[2]
    rows = u.shape[0]
    cols = u.shape[1]
    for r in range(rows):
        for c in range(cols):
            if valid[r, c] == 0:
                for b in range(bands):
                    out[b, r, c] = nodata
                continue
            x = min(max(u[r, c], 0.0), width - 1.0)
            y = min(max(v[r, c], 0.0), height - 1.0)
            if bilinear:
                x0 = min(int(x), width - 2) if width > 1 else 0
                y0 = min(int(y), height - 2) if height > 1 else 0
                ax = x - x0
                ay = y - y0
                x1 = min(x0 + 1, width - 1)
                y1 = min(y0 + 1, height - 1)
                for b in range(bands):
                    val = ((1.0 - ay) * ((1.0 - ax) * image[b, y0, x0] + ax * image[b, y0, x1])
                           + ay * ((1.0 - ax) * image[b, y1, x0] + ax * image[b, y1, x1]))
                    if is_int:  # a weighted mean of values in range stays in range: rounding is enough
                        val = np.floor(val + 0.5)
                    out[b, r, c] = val
            else:
                xi = int(np.floor(x + 0.5))
                yi = int(np.floor(y + 0.5))
                for b in range(bands):
                    out[b, r, c] = image[b, yi, xi]


__all__ = ["N_NODE", "block_boxes", "fold_tiles", "hide_folded", "node_count", "node_index", "project_cells",
           "rasterize_depth", "sample_bands"]
