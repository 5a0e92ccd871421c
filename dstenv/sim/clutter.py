"""Street clutter of the procedural city: poles, signs, trees, hedges, fences, bins,
bollards, parked bicycles and bus shelters.

Clutter is what a real LIDAR sees on every street and a map (OSM) does not hold:
static, occupied, neither building nor road user. It is placed per block side,
measured from the kerb line into the block (see :func:`place_clutter`):

* the kerb line of street furniture: on a side with a parking strip at the road
  edge of the sidewalk (``curb + 0.25`` m), on a side without one in the middle of
  the verge (``curb / 2``): poles every ``pole_spacing``, rows of trees on some
  sides, signs, bins and parked bicycles at random places, bollards at some block
  corners, bus shelters on some sides without parking;
* the building front, just behind the sidewalk (``curb + sw + 0.4`` m): hedges and
  fences along part of the front yards, never into a building.

Nothing stands on a crosswalk or under a parked vehicle; furniture keeps to the kerb
edge of the sidewalk, clear of the middle where pedestrians walk. All
randomness comes from the generator passed in (a child stream of the city's).
The result is an :class:`~dstenv.sim.types.Obstacles` (boxes with heights, see
:mod:`dstenv.sim.types`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from dstenv.sim.types import ObstacleKind as K
from dstenv.sim.kerbside import kerb_clutter
from dstenv.sim.types import Obstacles

__all__ = ["default_clutter_config", "place_clutter", "street_clutter", "median_clutter",
           "obstacles_from", "concat_obstacles", "Side"]

#: one block side: ``(start (2,), along (2,), inward (2,), length [m], has parking)``
Side = tuple[np.ndarray, np.ndarray, np.ndarray, float, bool]


def default_clutter_config() -> dict[str, Any]:
    """The ``world.clutter`` section (units in comments; rates per 100 m of kerb)."""
    return {
        "density": 1.0,  # [-] scales every rate and probability below (0: no clutter)
        "pole_spacing": 28.0,  # [m] street lights / utility poles along every kerb
        "tree_side_prob": 0.55,  # [-] share of block sides lined with trees
        "tree_spacing": 9.0,  # [m] between the trees of a row
        "sign_rate": 3.0,  # [1/100 m] sign posts
        "bin_rate": 2.5,  # [1/100 m] waste bins
        "bicycle_rate": 1.5,  # [1/100 m] groups of 2-6 parked bicycles
        "bollard_prob": 0.3,  # [-] chance of a row of bollards at each end of a side
        "shelter_prob": 0.15,  # [-] chance of a bus shelter on a side without parking
        "front_prob": 0.45,  # [-] share of front-yard stretches with a hedge or fence
    }


def _rows() -> dict[str, list]:
    return {k: [] for k in ("xy", "yaw", "length", "width", "z_min", "z_max", "kind")}


def _obstacles(rows: dict[str, list]) -> Obstacles:
    """The collected rows as :class:`Obstacles` (empty when no row was added)."""
    if not rows["yaw"]:
        return Obstacles.empty()
    f = np.float64
    return Obstacles(np.array(rows["xy"], f).reshape(-1, 2), np.array(rows["yaw"], f),
                     np.array(rows["length"], f), np.array(rows["width"], f),
                     np.array(rows["z_min"], f), np.array(rows["z_max"], f),
                     np.array(rows["kind"], np.uint8))


def obstacles_from(items: list[tuple]) -> Obstacles:
    """:class:`Obstacles` from ``(xy, yaw, length, width, z_min, z_max, kind)`` tuples."""
    rows = _rows()
    for item in items:
        _add(rows, *item)
    return _obstacles(rows)


def concat_obstacles(parts: list[Obstacles]) -> Obstacles:
    """All boxes of ``parts`` in one :class:`Obstacles` (in order)."""
    return Obstacles(*(np.concatenate([getattr(p, f) for p in parts])
                       for f in ("xy", "yaw", "length", "width", "z_min", "z_max", "kind")))


def median_clutter(boxes: list[tuple[np.ndarray, np.ndarray]], cfg: dict[str, Any],
                   rng: np.random.Generator | None) -> Obstacles:
    """Street furniture on raised medians: a row of trees on some (``tree_side_prob``),
    poles every ``pole_spacing``, a keep-right sign post at each end.

    Args:
        boxes: axis-aligned medians as ``(low (2,), high (2,))`` corners [m].
        cfg: the ``world.clutter`` section.

    Returns:
        :class:`Obstacles` on the median centre-lines (empty when ``density`` is 0).
    """
    dens = float(cfg["density"])
    if dens <= 0 or not boxes or rng is None:
        return Obstacles.empty()
    rows = _rows()
    for lo, hi in boxes:
        ext = hi - lo
        ax = int(np.argmax(ext))
        along = np.eye(2)[ax]
        start = lo + np.eye(2)[1 - ax] * ext[1 - ax] / 2
        length, width = float(ext[ax]), float(ext[1 - ax])
        yaw = float(np.arctan2(along[1], along[0]))
        if length < 4.0:
            continue
        for s in (0.6, length - 0.6):
            _add(rows, start + along * s, yaw, 0.1, 0.1, 0.0, 2.3, K.SIGN)
        if width >= 1.5 and rng.random() < min(cfg["tree_side_prob"] * dens, 1.0):
            sp = cfg["tree_spacing"]
            for s in np.arange(3.0 + rng.uniform(0, sp / 2), length - 3.0, sp):
                zc = rng.uniform(2.0, 3.0)
                r_trunk = rng.uniform(0.12, min(0.25, width / 4))
                c = rng.uniform(3.0, 6.0)
                _add(rows, start + along * s, yaw, 2 * r_trunk, 2 * r_trunk, 0.0, zc + 0.5,
                     K.TREE_TRUNK)
                _add(rows, start + along * s, yaw, c, c, zc, zc + rng.uniform(3.0, 6.0),
                     K.TREE_CROWN)
        else:
            spacing = cfg["pole_spacing"] / dens
            for s in np.arange(2.0 + rng.uniform(0, spacing), length - 2.0, spacing):
                _add(rows, start + along * s, yaw, 0.26, 0.26, 0.0, rng.uniform(6.0, 9.0), K.POLE)
    return _obstacles(rows)


def _add(rows, xy, yaw, length, width, z0, z1, kind) -> None:
    for k, v in zip(rows, (xy, yaw, length, width, z0, z1, int(kind))):
        rows[k].append(v)


def place_clutter(sides: list[Side], buildings: list[np.ndarray], slots: np.ndarray,
                  avoid: np.ndarray, curb: float, sidewalk: float, cfg: dict[str, Any],
                  rng: np.random.Generator) -> Obstacles:
    """Clutter along the block sides of a city.

    Args:
        sides: the block sides (:data:`Side`), kerb line first.
        buildings: building footprints (``(4, 2)`` rectangles or any polygons).
        slots: ``(S, 6)`` parking slots ``x, y, yaw, length, width, height`` (a
            length of 0 means a standard 6 m slot).
        avoid: ``(P, 2)`` crosswalk ends (kept clear by 2.5 m).
        curb, sidewalk: kerb strip and sidewalk width [m].
        cfg: the ``world.clutter`` section.

    Returns:
        :class:`Obstacles` (empty when ``density`` is 0).
    """
    dens = float(cfg["density"])
    if dens <= 0 or not sides:
        return Obstacles.empty()
    bbox = _bboxes(buildings)
    geo = np.array([[*start, *along, *inward, length] for start, along, inward, length, _ in sides],
                   np.float64).reshape(-1, 7)
    yaws = np.arctan2(geo[:, 3], geo[:, 2])
    slots = np.asarray(slots, np.float64).reshape(-1, 6)
    params = np.array([cfg[k] for k in ("pole_spacing", "tree_side_prob", "tree_spacing",
                                        "sign_rate", "bin_rate", "bicycle_rate", "bollard_prob",
                                        "shelter_prob", "front_prob")], np.float64)
    rows = kerb_clutter(rng, geo, np.array([bool(s[4]) for s in sides]), yaws, bbox, slots,
                        np.cos(slots[:, 2]), np.sin(slots[:, 2]),
                        np.where(slots[:, 3] > 0, slots[:, 3] / 2, 3.0),
                        np.where(slots[:, 4] > 0, slots[:, 4] / 2, 1.0),
                        np.asarray(avoid, np.float64).reshape(-1, 2), float(curb),
                        float(sidewalk), dens, params)
    if not len(rows):
        return Obstacles.empty()
    return Obstacles(rows[:, :2].copy(), rows[:, 2].copy(), rows[:, 3].copy(), rows[:, 4].copy(),
                     rows[:, 5].copy(), rows[:, 6].copy(), rows[:, 7].astype(np.uint8))


def _bboxes(polys: list[np.ndarray]) -> np.ndarray:
    """``(P, 4) float64`` rows ``x_min, y_min, x_max, y_max`` of polygons ``(K_i, 2)``,
    all in one reduction (a city has hundreds of buildings)."""
    cnt = np.array([len(p) for p in polys], np.int64)
    if not len(polys) or (cnt == 0).any():
        return np.array([[*np.min(b, 0), *np.max(b, 0)] for b in polys]).reshape(-1, 4)
    flat = np.concatenate(polys).astype(np.float64, copy=False)
    starts = np.concatenate([[0], np.cumsum(cnt)[:-1]])
    return np.concatenate([np.minimum.reduceat(flat, starts), np.maximum.reduceat(flat, starts)],
                          1)


def street_clutter(world_map: Any, cfg: dict[str, Any], rng: np.random.Generator) -> Obstacles:
    """Clutter beside the streets of any map with ``streets`` and
    ``meta["street_half_widths"]`` (an OSM map): poles, trees, signs and bins 0.8-2 m
    beyond both road edges, where the ground is :attr:`MapClass.INTERMEDIATE` for 0.8 m
    around (clear of roads and buildings)."""
    from dstenv.sim.raster import lookup
    from dstenv.sim.types import MapClass

    dens = float(cfg["density"])
    half = world_map.meta.get("street_half_widths")
    if dens <= 0 or half is None or not len(world_map.streets):
        return Obstacles.empty()
    rows = _rows()
    ring = 0.8 * np.array([[0, 0], [1, 0], [-1, 0], [0, 1], [0, -1]])
    trees = cfg["tree_side_prob"] * dens
    for line, hw in zip(world_map.streets, half):
        seg = np.diff(line, axis=0)
        cum = np.concatenate([[0.0], np.cumsum(np.hypot(*seg.T))])
        for side in (-1.0, 1.0):
            tree_row = rng.random() < trees
            spacing = cfg["tree_spacing"] if tree_row else cfg["pole_spacing"] / dens
            for s in np.arange(rng.uniform(0, spacing), cum[-1], spacing):
                k = min(int(np.searchsorted(cum, s, side="right")) - 1, len(seg) - 1)
                d = seg[k] / max(np.hypot(*seg[k]), 1e-9)
                normal = side * np.array([-d[1], d[0]])
                p = line[k] + d * (s - cum[k]) + normal * (hw + rng.uniform(0.8, 2.0))
                if not (lookup(world_map, p + ring) == MapClass.INTERMEDIATE).all():
                    continue
                yaw = float(np.arctan2(d[1], d[0]))
                if tree_row:
                    r, zc = rng.uniform(0.12, 0.25), rng.uniform(2.0, 3.0)
                    _add(rows, p, yaw, 2 * r, 2 * r, 0.0, zc + 0.5, K.TREE_TRUNK)
                    c = rng.uniform(3.0, 6.5)
                    _add(rows, p, yaw, c, c, zc, zc + rng.uniform(3.0, 7.0), K.TREE_CROWN)
                else:
                    kind = (K.POLE, K.SIGN, K.BIN)[int(rng.choice(3, p=[0.6, 0.25, 0.15]))]
                    size = {K.POLE: 0.26, K.SIGN: 0.1, K.BIN: 0.6}[kind]
                    _add(rows, p, yaw, size, size, 0.0,
                         {K.POLE: 7.0, K.SIGN: 2.3, K.BIN: 1.0}[kind], kind)
    return _obstacles(rows)
