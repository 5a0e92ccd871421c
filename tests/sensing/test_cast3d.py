"""The 3-D LIDAR's culled casting equals testing every beam against every occluder."""

from __future__ import annotations

import math

import numpy as np

from dstenv.sensing.cast3d import (
    cast_boxes,
    cast_ground,
    cast_walls,
    column_index,
)
from dstenv.sensing.raised import raised_distance

MOUNT = 1.73


def _beams(columns=180, channels=16, yaw_rate=0.02, drift=(0.03, -0.01)):
    """Skewed columns (the origin moves, the spin is not exactly 360 deg) and channels."""
    j = np.arange(columns)
    az = 0.3 + (math.pi - j * 2 * math.pi / columns) * (1.0 - yaw_rate)
    ox, oy = drift[0] * j, drift[1] * j
    slope = np.tan(np.deg2rad(np.linspace(2.0, -24.9, channels)))
    return ox, oy, az, slope


def _buffers(columns, channels):
    return (np.full((columns, channels), np.inf), np.full((columns, channels), -1, np.int16),
            np.full((columns, channels), -1, np.int32))


def _random_boxes(rng, k=40):
    rows = []
    while len(rows) < k:
        cx, cy = rng.uniform(-35, 35, 2)
        hl, hw = rng.uniform(0.15, 4.0, 2)
        if math.hypot(cx, cy) < 2 * max(hl, hw) + 6:
            continue  # keep every origin outside the boxes
        z = [(0.0, 1.5), (1.8, 8.0), (0.0, 25.0), (0.5, 2.5)][len(rows) % 4]
        yaw = rng.uniform(-math.pi, math.pi)
        rows.append([cx, cy, math.cos(yaw), math.sin(yaw), hl, hw, *z, 4, len(rows),
                     math.hypot(hl, hw)])
    return np.array(rows)


def _reference_boxes(boxes, ox, oy, ux, uy, slope):
    """Every beam against every box (the module docstring's rule, plain Python)."""
    best, surf, idx = _buffers(len(ux), len(slope))
    for j in range(len(ux)):
        for k, (cx, cy, ca, sa, hl, hw, zlo, zhi, s, ind, _) in enumerate(boxes):
            px, py = ca * (ox[j] - cx) + sa * (oy[j] - cy), -sa * (ox[j] - cx) + ca * (oy[j] - cy)
            dx, dy = ca * ux[j] + sa * uy[j], -sa * ux[j] + ca * uy[j]
            t0, t1 = -np.inf, np.inf
            for p, d, half in ((px, dx, hl), (py, dy, hw)):
                if abs(d) < 1e-12:
                    if abs(p) > half:
                        t0, t1 = 1.0, 0.0
                    continue
                a, b = (-half - p) / d, (half - p) / d
                t0, t1 = max(t0, min(a, b)), min(t1, max(a, b))
            if t1 < t0 or t0 < 0:
                continue
            for c, sl in enumerate(slope):
                z0 = MOUNT + sl * t0
                if zlo <= z0 <= zhi:
                    t = t0
                elif z0 > zhi and sl < 0:
                    t = (zhi - MOUNT) / sl
                elif z0 < zlo and sl > 0:
                    t = (zlo - MOUNT) / sl
                else:
                    continue
                if t <= t1 and t < best[j, c]:
                    best[j, c], surf[j, c], idx[j, c] = t, int(s), int(ind)
    return best, surf, idx


def test_boxes_culled_by_azimuth_and_slope_match_every_beam_against_every_box():
    rng = np.random.default_rng(0)
    ox, oy, az, slope = _beams()
    ux, uy = np.cos(az), np.sin(az)
    boxes = _random_boxes(rng)
    out = _buffers(len(az), len(slope))
    cast_boxes(boxes, *column_index(ox, oy, az), ox, oy, ux, uy, slope, -slope, MOUNT, 120.0,
               *out)
    ref = _reference_boxes(boxes, ox, oy, ux, uy, slope)
    assert np.isfinite(out[0]).mean() > 0.1  # the scene is not empty
    for a, b in zip(out, ref, strict=True):
        assert np.array_equal(a, b)


def _random_buildings(rng: np.random.Generator, vertices: int, spread: float, clear: float,
                      *, tries: int = 0, count: int = 0
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Random star-shaped footprints centred in ``[-spread, spread]^2`` and at least
    ``clear`` m from the sensor: ``tries`` draws (some dropped) or exactly ``count``.

    Returns:
        ``edges (E, 4)``, ``starts (P + 1,)``, bounding ``circles (P, 3)``.
    """
    edges, starts, circles = [], [0], []
    drawn = 0
    while (drawn < tries) if tries else (len(circles) < count):
        drawn += 1
        c = rng.uniform(-spread, spread, 2)
        if np.hypot(*c) < clear:
            continue
        ang = np.sort(rng.uniform(0, 2 * math.pi, vertices))
        poly = c + rng.uniform(2, 8, (vertices, 1)) * np.stack([np.cos(ang), np.sin(ang)], 1)
        edges.append(np.concatenate([poly, np.roll(poly, -1, 0)], 1))
        starts.append(starts[-1] + vertices)
        circles.append([*c, 8.0])
    return np.concatenate(edges), np.array(starts), np.array(circles)


def test_walls_culled_equal_all_columns():
    rng = np.random.default_rng(1)
    ox, oy, az, slope = _beams(columns=720, channels=32)
    ux, uy = np.cos(az), np.sin(az)
    edges, starts, circles = _random_buildings(rng, 5, 60.0, 15.0, tries=25)
    heights = rng.uniform(2.0, 30.0, len(circles))
    results = []
    for drift in (None, np.inf):  # np.inf: every column tests every building
        order, sorted_az, rx, ry, d = column_index(ox, oy, az)
        out = _buffers(len(az), len(slope))
        cast_walls(edges, starts, circles, heights, 2, order, sorted_az, rx, ry,
                   d if drift is None else drift, ox, oy, ux, uy, slope, -slope, MOUNT, 120.0,
                   *out)
        results.append(out)
    assert np.isfinite(results[0][0]).mean() > 0.05
    for a, b in zip(*results, strict=True):
        assert np.array_equal(a, b)


def test_walls_match_every_beam_against_every_edge():
    """Only the nearest crossing of a building at least as tall as the mount is walked;
    every crossing of a lower one (a wall, a fence): the same as testing every edge."""
    rng = np.random.default_rng(3)
    ox, oy, az, slope = _beams(columns=240, channels=24)
    ux, uy = np.cos(az), np.sin(az)
    edges, starts, circles = _random_buildings(rng, 6, 40.0, 14.0, count=16)
    heights = np.where(np.arange(16) % 3 == 0, rng.uniform(0.3, 1.6, 16),  # below the mount
                       rng.uniform(2.0, 30.0, 16))
    out = _buffers(len(az), len(slope))
    cast_walls(edges, starts, circles, heights, 2, *column_index(ox, oy, az), ox, oy, ux, uy,
               slope, -slope, MOUNT, 120.0, *out)
    ref = _buffers(len(az), len(slope))
    for j in range(len(az)):
        for b in range(len(circles)):
            for ax0, ay0, ax1, ay1 in edges[starts[b]:starts[b + 1]]:
                ax, ay, ex, ey = ax0 - ox[j], ay0 - oy[j], ax1 - ax0, ay1 - ay0
                den = ux[j] * ey - uy[j] * ex
                if den == 0.0:
                    continue
                t = (ax * ey - ay * ex) / den
                sp = (ax * uy[j] - ay * ux[j]) / den
                if t < 0.0 or not 0.0 <= sp <= 1.0:
                    continue
                z = MOUNT + slope * t
                hit = (t < ref[0][j]) & (z >= 0.0) & (z <= heights[b])
                ref[0][j][hit], ref[1][j][hit], ref[2][j][hit] = t, 2, b
    assert (ref[2] >= 0).mean() > 0.1 and np.isin(ref[2], np.flatnonzero(heights < MOUNT)).any()
    for a, b in zip(out, ref, strict=True):
        assert np.array_equal(a, b)


def test_ground_walk_jumps_land_where_the_cell_walk_does():
    rng = np.random.default_rng(2)
    raster = np.full((500, 500), 2, np.uint8)  # road, 0.2 m cells, origin (-50, -50)
    for _ in range(60):  # raised patches (kerbs, islands) of all sizes
        r, c = rng.integers(0, 500, 2)
        h, w = rng.integers(1, 40, 2)
        raster[r:r + h, c:c + w] = 3
    raster[240:260, 240:260] = 2  # the sensor stands on the road
    ox, oy, az, slope = _beams(columns=720, channels=64, drift=(0.002, 0.001))
    ux, uy = np.cos(az), np.sin(az)
    dist = raised_distance(raster, 3)
    assert dist.max() > 5
    results = []
    # zeros: cell by cell everywhere; then blocks of 2 x 2 and 4 x 4 cells
    for d, shift in ((dist, 0), (np.zeros_like(dist), 0), (raised_distance(raster, 3, 1), 1),
                     (raised_distance(raster, 3, 2), 2)):
        out = _buffers(len(az), len(slope))
        cast_ground(raster, d, shift, np.uint8(3), -50.0, -50.0, 0.2, 0.12, ox, oy, ux, uy,
                    slope, MOUNT, 120.0, *out)
        results.append(out)
    b0, s0, i0 = results[0]
    assert (s0 == 1).sum() > 1000 and (s0 == 0).sum() > 1000  # kerbs and road both hit
    for b1, s1, i1 in results[1:]:
        assert np.array_equal(s0, s1) and np.array_equal(i0, i1)
        assert np.allclose(b0, b1, rtol=0, atol=1e-9)
