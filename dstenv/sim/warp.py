"""A smooth warp of the plane that turns the procedural grid city into curved and
diagonal streets with irregular blocks.

The city is laid out on a Manhattan grid first; then every piece of geometry (lane
points, junctions, buildings, parking slots, clutter, street centre-lines and the
surface rasters) goes through one seeded map ``W`` of the plane:

1. a bend along x: ``x1 = x + ax sin(2 pi y / lx + px)`` (streets along y curve);
2. a bend along y: ``y2 = y + ay sin(2 pi x1 / ly + py)`` (streets along x curve);
3. a linear shear ``M`` about the map centre whose columns are ``theta`` apart from
   90 deg: streets meet at ``90 +- theta`` deg; the columns have length
   ``1 / cos(theta)``, so street widths are kept and street lengths grow by that
   factor (3.5 % at 15 deg);
4. a translation that puts the warped map back at the raster origin.

Each step is invertible in closed form, so rasters are re-sampled exactly (nearest
cell) through the inverse map. Bend slopes ``2 pi a / l`` stay small (validated
<= 0.3), so widths and lengths change by a few percent and lane curvature stays
gentle (radius >= ``l^2 / (4 pi^2 a)``, ~250 m at the defaults).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numba as nb
import numpy as np

from dstenv.sim.lanes import SPACING, NetworkBuilder
from dstenv.sim.lanegeom import resample_many
from dstenv.sim.types import Obstacles

__all__ = ["Warp", "draw_warp", "kerb_ease", "warp_lanes", "warp_boxes", "warp_obstacles"]

TAU = 2.0 * np.pi


@dataclass
class Warp:
    """The parameters of one warp (see the module doc).

    Attributes:
        ax, lx, px: amplitude [m], wavelength [m] and phase [rad] of the bend along x.
        ay, ly, py: the same along y.
        theta: junction angle offset [rad] of the shear (0: right angles).
        centre: ``(2,) float64`` fixed point of the shear [m].
        shift: ``(2,) float64`` translation applied last [m].
    """

    ax: float
    lx: float
    px: float
    ay: float
    ly: float
    py: float
    theta: float
    centre: np.ndarray
    shift: np.ndarray

    @property
    def matrix(self) -> np.ndarray:
        """``(2, 2) float64`` shear: x axis turned by ``-theta/2``, y axis by ``+theta/2``,
        both stretched by ``1 / cos(theta)`` so that street widths are kept."""
        h = self.theta / 2
        return np.array([[np.cos(h), -np.sin(h)], [-np.sin(h), np.cos(h)]]) / np.cos(self.theta)

    def _params(self) -> np.ndarray:
        m = np.linalg.inv(self.matrix)
        return np.array([self.ax, TAU / self.lx, self.px, self.ay, TAU / self.ly, self.py,
                         m[0, 0], m[0, 1], m[1, 0], m[1, 1],
                         self.centre[0], self.centre[1], self.shift[0], self.shift[1]])

    def points(self, xy: np.ndarray) -> np.ndarray:
        """Warp points: ``(..., 2) float64`` -> ``(..., 2) float64`` [m]."""
        xy = np.asarray(xy, np.float64)
        x = xy[..., 0] + self.ax * np.sin(TAU * xy[..., 1] / self.lx + self.px)
        y = xy[..., 1] + self.ay * np.sin(TAU * x / self.ly + self.py)
        p = np.stack([x - self.centre[0], y - self.centre[1]], -1) @ self.matrix.T
        return p + self.centre + self.shift

    def headings(self, xy: np.ndarray, yaw: np.ndarray) -> np.ndarray:
        """Headings [rad] at points ``xy (N, 2)`` after the warp: ``yaw (N,)`` -> ``(N,)``
        (the direction ``(cos yaw, sin yaw)`` through the warp's Jacobian)."""
        xy = np.asarray(xy, np.float64).reshape(-1, 2)
        d = np.stack([np.cos(yaw), np.sin(yaw)], -1).reshape(-1, 2)
        ka, kb = TAU / self.lx, TAU / self.ly
        da = self.ax * ka * np.cos(ka * xy[:, 1] + self.px)  # d x1 / d y
        x1 = xy[:, 0] + self.ax * np.sin(ka * xy[:, 1] + self.px)
        db = self.ay * kb * np.cos(kb * x1 + self.py)  # d y2 / d x1
        d1 = np.stack([d[:, 0] + da * d[:, 1], d[:, 1]], -1)
        d2 = np.stack([d1[:, 0], d1[:, 1] + db * d1[:, 0]], -1) @ self.matrix.T
        return np.arctan2(d2[:, 1], d2[:, 0]).reshape(np.shape(yaw))

    def inverse(self, xy: np.ndarray) -> np.ndarray:
        """Exact inverse of :meth:`points`: ``(..., 2) float64`` -> ``(..., 2)`` [m]."""
        xy = np.asarray(xy, np.float64)
        p = (xy - self.centre - self.shift) @ np.linalg.inv(self.matrix).T + self.centre
        y = p[..., 1] - self.ay * np.sin(TAU * p[..., 0] / self.ly + self.py)
        x = p[..., 0] - self.ax * np.sin(TAU * y / self.lx + self.px)
        return np.stack([x, y], -1)

    def polylines(self, polys: list[np.ndarray], step: float = 5.0) -> list[np.ndarray]:
        """Warp polylines, each first split so that no piece is longer than ``step`` [m]
        (a straight street becomes a curve): ``(K, 2)`` each -> ``(M, 2) float64`` each.
        All pieces of all lines in one pass (a city has hundreds of buildings)."""
        if not polys:
            return []
        sizes = np.array([len(p) for p in polys])
        pts = np.concatenate(polys).astype(np.float64)
        line = np.repeat(np.arange(len(polys)), sizes)
        inner = line[:-1] == line[1:]  # segments within one line
        a, b = pts[:-1][inner], pts[1:][inner]
        n = np.maximum(np.ceil(np.hypot(*(b - a).T) / step), 1).astype(np.int64)
        k = np.repeat(np.arange(len(a)), n)
        t = (np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n) + 1) / np.repeat(n, n)
        dense = a[k] + t[:, None] * (b - a)[k]
        firsts = np.cumsum(sizes) - sizes
        # each line: its first point, then the pieces of its segments, in order
        owner = np.concatenate([line[firsts], np.repeat(line[:-1][inner], n)])
        order = np.argsort(owner, kind="stable")
        out = self.points(np.concatenate([pts[firsts], dense]))[order]
        counts = np.bincount(owner, minlength=len(polys))
        return np.split(out, np.cumsum(counts)[:-1])

    def raster(self, src: np.ndarray, shape: tuple[int, int], resolution: float,
               fill: int) -> np.ndarray:
        """Re-sample a raster (origin ``(0, 0)``) through the warp.

        Args:
            src: ``(H, W) uint8`` raster of the unwarped city.
            shape: ``(H2, W2)`` of the output (also with origin ``(0, 0)``).
            resolution: cell size of both [m].
            fill: code of output cells whose source lies outside the input.

        Returns:
            ``(H2, W2) uint8``: each cell takes the source cell under its inverse image
            (nearest cell).
        """
        out = np.empty(shape, np.uint8)
        _resample(np.ascontiguousarray(src), out, self._params(), float(resolution),
                  np.uint8(fill), 16)
        return out


@nb.njit(cache=True)
def _source(q, u, v):  # pragma: no cover - numba
    """Inverse warp of one point, ``u, v`` relative to ``centre + shift``."""
    x2 = q[6] * u + q[7] * v + q[10]
    y2 = q[8] * u + q[9] * v + q[11]
    y = y2 - q[3] * np.sin(q[4] * x2 + q[5])
    return x2 - q[0] * np.sin(q[1] * y + q[2]), y


#: Side of the source tiles whose uniformity :func:`_resample` tests [cells].
TILE = 16
#: Output columns of a group whose two ends :func:`_resample` evaluates first (a multiple
#: of the exact-evaluation step, 16): the runs inside whose source footprint is one
#: uniform class then need no exact evaluation.
GROUP = 64


@nb.njit(cache=True)
def _tile_classes(src, tile):  # pragma: no cover - numba
    """``(ceil(H / tile), ceil(W / tile)) int16``: the class of each ``tile x tile``
    block of ``src (H, W) uint8`` when all its cells hold it, -1 when mixed (the
    blocks of the last row / column are the cells that are left)."""
    h, w = src.shape
    th, tw = (h + tile - 1) // tile, (w + tile - 1) // tile
    out = np.empty((th, tw), np.int16)
    diff = np.empty(w, np.uint8)
    for tr in range(th):
        r0, r1 = tr * tile, min(tr * tile + tile, h)
        first = src[r0]
        diff[:] = 0
        for r in range(r0 + 1, r1):  # rows against the tile row's first (vectorised)
            row = src[r]
            for c in range(w):
                diff[c] |= row[c] ^ first[c]
        for tc in range(tw):
            c0, c1 = tc * tile, min(tc * tile + tile, w)
            v = first[c0]
            ok = True
            for c in range(c0, c1):
                if diff[c] != 0 or first[c] != v:
                    ok = False
                    break
            out[tr, tc] = np.int16(v) if ok else np.int16(-1)
    return out


@nb.njit(cache=True)
def _curvature(q):  # pragma: no cover - numba
    """An upper bound of ``|d^2 x / du^2|`` and ``|d^2 y / du^2|`` of the inverse warp
    along an output row [1/m]: from :func:`_source`, ``y'' = ay ky^2 m00^2 sin`` and
    ``x'' = ax kx^2 y'^2 sin - ax kx y'' cos`` with ``|y'| <= |m10| + ay ky |m00|``."""
    ypp = abs(q[3]) * q[4] * q[4] * q[6] * q[6]
    yp = abs(q[8]) + abs(q[3]) * q[4] * abs(q[6])
    xpp = abs(q[0]) * q[1] * q[1] * yp * yp + abs(q[0]) * q[1] * ypp
    return max(xpp, ypp)


@nb.njit(cache=True)
def _uniform(tiles, tile, h, w, xa, ya, xb, yb, pad):  # pragma: no cover - numba
    """The one class of every source cell that a group with exact ends ``(xa, ya)``,
    ``(xb, yb)`` [cells] can take, ``pad`` [cells] being a bound of how far its
    cells stray from the chord; -1 when unknown (mixed tiles or at the border),
    -2 when all lie outside the source (the fill)."""
    x_lo, x_hi = min(xa, xb) - pad, max(xa, xb) + pad
    y_lo, y_hi = min(ya, yb) - pad, max(ya, yb) + pad
    if x_hi < 0.0 or y_hi < 0.0 or x_lo >= w or y_lo >= h:
        return -2
    if x_lo < 0.0 or y_lo < 0.0 or x_hi >= w or y_hi >= h:
        return -1
    c0, c1 = int(x_lo) // tile, int(x_hi) // tile
    r0, r1 = int(y_lo) // tile, int(y_hi) // tile
    v = tiles[r0, c0]
    for tr in range(r0, r1 + 1):
        for tc in range(c0, c1 + 1):
            if tiles[tr, tc] != v:
                return -1
    return v


@nb.njit(cache=True)
def _resample(src, out, q, res, fill, step):  # pragma: no cover - numba
    """Nearest-cell re-sampling; the inverse map is evaluated exactly every ``step``
    columns and linearly in between (its curvature is tiny: < 1 cm off at 16 cells).

    Cells step in fixed point (1/65536 cell), so a run's positions are monotone
    between its ends: a run whose two ends fall inside the source is copied without
    per-cell bounds tests. Flat unsigned indices (no negative-index wrap-around).

    Shortcut, same cells: the ends of each group of :data:`GROUP` columns (run ends
    too) are evaluated first. Every exact point between them stays within ``pad`` of
    their chord (its sag under :func:`_curvature`, doubled, plus a cell for the
    fixed-point steps), so when that widened chord lies inside uniform source tiles
    (:func:`_tile_classes`) or wholly outside the source, all cells of the group
    take that class whatever their exact positions, and the ``sin`` of the runs
    inside are not needed. Other groups are stepped run by run as before, from the
    same run ends computed with the same arithmetic."""
    h, w = src.shape
    n_r, n_c = out.shape
    a, b = src.ravel(), out.ravel()
    hu, wu, one = np.uint64(h), np.uint64(w), np.uint64(1)
    tiles = _tile_classes(src, TILE)
    group = max(GROUP // step, 1) * step
    span = group * res  # chord sag L^2 / 8 max|g''| [m], doubled, in cells; + 1 cell
    pad = 2.0 * span * span / 8.0 * _curvature(q) / res + 1.0
    n_g = (n_c + group - 1) // group
    gx, gy = np.empty(n_g + 1), np.empty(n_g + 1)
    for r in range(n_r):
        v = (r + 0.5) * res - q[11] - q[13]
        for k in range(n_g + 1):  # the group ends first: their sin pipeline
            gx[k], gy[k] = _source(q, (min(k * group, n_c) + 0.5) * res - q[10] - q[12], v)
        xa, ya = gx[0], gy[0]
        o_row = np.uint64(r * n_c)
        for g0 in range(0, n_c, group):
            g1 = min(g0 + group, n_c)
            xg, yg = gx[g0 // group + 1], gy[g0 // group + 1]
            cls = _uniform(tiles, TILE, h, w, xa / res, ya / res, xg / res, yg / res, pad)
            if cls != -1:
                val = fill if cls == -2 else np.uint8(cls)
                for o in range(o_row + np.uint64(g0), o_row + np.uint64(g1)):
                    b[o] = val
                xa, ya = xg, yg
                continue
            for c0 in range(g0, g1, step):
                c1 = min(c0 + step, n_c)
                if c1 == g1:
                    xb, yb = xg, yg
                else:
                    xb, yb = _source(q, (c1 + 0.5) * res - q[10] - q[12], v)
                n = c1 - c0
                xi, yi = np.int64(xa / res * 65536.0), np.int64(ya / res * 65536.0)
                dx = np.int64((xb - xa) / res * 65536.0 / n)
                dy = np.int64((yb - ya) / res * 65536.0 / n)
                xa, ya = xb, yb
                o = o_row + np.uint64(c0)
                xl, yl = xi + (n - 1) * dx, yi + (n - 1) * dy
                if (np.uint64(xi >> 16) < wu and np.uint64(yi >> 16) < hu
                        and np.uint64(xl >> 16) < wu and np.uint64(yl >> 16) < hu):
                    for _ in range(n):
                        b[o] = a[np.uint64((yi >> 16) * w + (xi >> 16))]
                        o += one
                        xi += dx
                        yi += dy
                else:
                    for _ in range(n):
                        cc, rr = np.uint64(xi >> 16), np.uint64(yi >> 16)  # < 0: huge
                        b[o] = a[rr * wu + cc] if rr < hu and cc < wu else fill
                        o += one
                        xi += dx
                        yi += dy


def draw_warp(cfg: dict[str, Any], size: tuple[float, float], rng: np.random.Generator
              ) -> tuple[Warp, tuple[float, float]] | None:
    """Draw a warp for a city of ``size = (width, height)`` [m] from the ``world.map``
    keys ``shear_deg``, ``bend_amplitude`` and ``bend_wavelength``.

    Returns:
        The warp and the ``(width, height)`` [m] of the warped map (its bounding box,
        moved to the origin), or None when both shear and bend are 0 (nothing drawn).
    """
    if cfg["shear_deg"] <= 0 and cfg["bend_amplitude"] <= 0:
        return None
    width, height = size
    theta = np.deg2rad(rng.uniform(-cfg["shear_deg"], cfg["shear_deg"]))
    amp = cfg["bend_amplitude"] * rng.uniform(0.5, 1.0, 2)
    wave = cfg["bend_wavelength"] * rng.uniform(0.85, 1.2, 2)
    phase = rng.uniform(0.0, TAU, 2)
    centre = np.array([width / 2, height / 2])
    warp = Warp(float(amp[0]), float(wave[0]), float(phase[0]), float(amp[1]),
                float(wave[1]), float(phase[1]), float(theta), centre, np.zeros(2))
    t, one = np.linspace(0.0, 1.0, 64), np.ones(64)
    edge = np.concatenate([np.stack([t * width, 0 * t], -1),
                           np.stack([t * width, one * height], -1),
                           np.stack([0 * t, t * height], -1),
                           np.stack([one * width, t * height], -1)])
    box = warp.points(edge)
    warp.shift = -box.min(0)
    ext = box.max(0) - box.min(0)
    return warp, (float(ext[0]), float(ext[1]))


def kerb_ease(shear_deg: float, gap: float) -> float:
    """How much larger [m] to paint the radius of the kerb corners of a city that a warp
    shears by up to ``shear_deg`` [deg], for right turns ``gap`` [m] from the kerb.

    A right turn goes round its kerb corner on an arc concentric with it, ``gap`` from
    it (:func:`dstenv.sim.roads.add_road_lanes`). The shear (:attr:`Warp.matrix`) keeps
    street widths but squeezes one diagonal of the plane by ``s = sqrt(1 - sin theta) /
    cos theta`` (its smaller singular value), so at two corners of every block the gap
    at mid-arc shrinks to ``s gap`` (11 % at 15 deg: a car's kerb-side clearance of
    ~0.5 m loses 0.2 m). A corner painted ``e`` larger moves the kerb back from the
    arc's middle by ``(sqrt(2) - 1) e`` and leaves the straights alone; ``e = gap (1 / s
    - 1) / (sqrt(2) - 1)`` restores the gap there (0 without shear, 0.5 m for 1.85 m
    at 15 deg)."""
    t = np.deg2rad(abs(shear_deg))
    s = np.sqrt(1.0 - np.sin(t)) / np.cos(t)
    return float(gap * (1.0 / s - 1.0) / (np.sqrt(2.0) - 1.0))


def warp_lanes(builder: NetworkBuilder, warp: Warp) -> None:
    """Warp every lane collected so far, in place (re-sampled to the even spacing)."""
    if not builder.polys:
        return
    ptr = np.cumsum([0] + [len(p) for p in builder.polys])
    # the lanes' points were already distinct and in order: re-sample without checks
    builder.polys = resample_many(warp.points(np.concatenate(builder.polys)), ptr, SPACING)


def warp_boxes(warp: Warp, rows: np.ndarray) -> np.ndarray:
    """Warp oriented boxes ``(N, >=3) float64`` rows ``x, y, yaw, ...`` (parking
    slots): centres moved, headings turned with the warp, sizes kept. Returns a copy."""
    rows = np.array(rows, np.float64)
    if len(rows):
        rows[:, 2] = warp.headings(rows[:, :2], rows[:, 2])
        rows[:, :2] = warp.points(rows[:, :2])
    return rows


def warp_obstacles(warp: Warp, obs: Obstacles) -> Obstacles:
    """Warp clutter boxes: centres moved, headings turned, sizes and heights kept."""
    if not len(obs):
        return obs
    return Obstacles(warp.points(obs.xy), warp.headings(obs.xy, obs.yaw), obs.length.copy(),
                     obs.width.copy(), obs.z_min.copy(), obs.z_max.copy(), obs.kind.copy())
