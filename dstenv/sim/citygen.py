"""Seeded procedural city: a street grid with T junctions, kerbside parking and buildings.

Streets run along x and y (Manhattan style) with varied spacing and 1-3 lanes
per direction. Some interior street segments are removed, which merges two blocks
and turns their junctions into T junctions. Each block gets, from the kerb in: a
curb strip (parking strip or verge), a sidewalk, a setback, then a row of
buildings of varied frontage and depth with gaps (alleys, driveways, empty lots).

Varied geometry (``world.map`` keys, all 0 in the ``clean`` scenario): wide streets
may get a raised median (:mod:`dstenv.sim.medians`), some 4-way junctions become
roundabouts (:mod:`dstenv.sim.roundabout`), and finally one smooth warp of the plane
(:mod:`dstenv.sim.warp`: shear and bends) turns the grid into diagonal and curved
streets with irregular blocks, applied to every lane, building, slot, obstacle,
street centre-line and raster alike.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from dstenv.sim.buildings import city_buildings
from dstenv.sim.lanes import Control, NetworkBuilder
from dstenv.sim.medians import draw_medians, median_box
from dstenv.sim.raster import (Surface, fill_polygons, fill_rect, fill_rects, fillet_corners,
                               scratch_raster)
from dstenv.sim.roads import RoadEdge, add_road_lanes
from dstenv.sim.roundabout import (island_clutter, paint_roundabout, pick_roundabouts,
                                   ring_nodes)
from dstenv.sim.sidewalks import LANE_OFFSET, add_block_rings
from dstenv.sim.clutter import concat_obstacles, median_clutter, place_clutter
from dstenv.sim.warp import Warp, draw_warp, kerb_ease, warp_boxes, warp_lanes, warp_obstacles
from dstenv.sim.lots import city_lots, clear_of_lots
from dstenv.sim.parking import SLOT_LENGTH, city_slots
from dstenv.sim.types import MapClass, WorldMap

__all__ = ["generate_city", "SLOT_LENGTH", "Warp"]

STOP_MARGIN = 4.4  # [m] stop line behind the crosswalk's outer walking line
BUILDING_STEP = 12.0  # [m] longest building edge after a warp (it follows curved streets)


def generate_city(cfg: dict[str, Any], traffic: dict[str, Any], rng: np.random.Generator,
                  clutter: dict[str, Any] | None = None) -> WorldMap:
    """Generate a city map from the ``map``, ``traffic`` and ``clutter`` config sections
    (no clutter when ``clutter`` is None).

    Returns:
        A :class:`WorldMap` with ``lanes`` a :class:`~dstenv.sim.lanes.LaneNetwork`
        and ``meta`` keys ``surface`` (``(Hm, Wm) uint8`` :class:`Surface` codes; of
        a warped city read it with :func:`~dstenv.sim.raster.surface_raster`),
        ``parking_slots`` (``(S, 6) float64`` x, y, yaw, length, width, height; see
        :mod:`dstenv.sim.parking`), ``kind``, ``warp`` (the :class:`Warp` applied,
        or None), ``roundabouts`` (``(R, 4) float64`` centre x, y, outer and island
        radius [m]), ``faces`` (block boxes before the warp); ``obstacles`` the street clutter
        (:mod:`dstenv.sim.clutter`); ``streets`` / ``street_lanes`` the centre-lines.

    Geometry jitter (lane width per street, kerb strip and sidewalk width per
    episode) and clutter draw from a child of ``rng``, so with them switched off the
    city is the same as without them.
    """
    real = rng.spawn(1)[0]
    # curved streets, roundabouts and medians draw from their own child stream, taken
    # only when one of them is on (so the clean city is the same as without them)
    geo = rng.spawn(1)[0] if _varied_geometry(cfg) else None
    cfg = dict(cfg)
    for key, jit in (("curb_strip_width", "curb_strip_jitter"),
                     ("sidewalk_width", "sidewalk_jitter")):
        if cfg[jit] > 0:
            cfg[key] = float(cfg[key] + real.uniform(-cfg[jit], cfg[jit]))
    lw, curb, sw = cfg["lane_width"], cfg["curb_strip_width"], cfg["sidewalk_width"]
    margin = cfg["margin"]
    nx, ny = cfg["blocks_x"] + 1, cfg["blocks_y"] + 1
    if nx < 2 or ny < 2:
        raise ValueError("map.blocks_x and map.blocks_y must be >= 1")
    spans = rng.uniform(cfg["block_min"], cfg["block_max"], nx + ny - 2)
    xs = margin + np.concatenate([[0], np.cumsum(spans[:nx - 1])])
    ys = margin + np.concatenate([[0], np.cumsum(spans[nx - 1:])])
    lanes_x = rng.integers(cfg["lanes_min"], cfg["lanes_max"] + 1, nx)
    lanes_y = rng.integers(cfg["lanes_min"], cfg["lanes_max"] + 1, ny)
    lwx, lwy = np.full(nx, lw), np.full(ny, lw)  # lane width of each street line [m]
    if cfg["lane_width_jitter"] > 0:
        jit = cfg["lane_width_jitter"]
        lwx, lwy = lw + real.uniform(-jit, jit, nx), lw + real.uniform(-jit, jit, ny)
    med_x, med_y = draw_medians(lanes_x, cfg, geo), draw_medians(lanes_y, cfg, geo)  # [m] widths
    hwx, hwy = lanes_x * lwx + med_x / 2, lanes_y * lwy + med_y / 2  # street half widths [m]

    # street segments (True = exists) and T junctions by merging neighbouring cells
    vseg = np.ones((nx, ny - 1), bool)  # x line i, from y_j to y_j+1
    hseg = np.ones((nx - 1, ny), bool)  # y line j, from x_i to x_i+1
    parent = {(i, j): (i, j) for i in range(nx - 1) for j in range(ny - 1)}
    merged: set[tuple[int, int]] = set()
    candidates = [("v", i, j) for i in range(1, nx - 1) for j in range(ny - 1)] + \
                 [("h", i, j) for i in range(nx - 1) for j in range(1, ny - 1)]
    for k in rng.permutation(len(candidates)):
        t, i, j = candidates[k]
        if rng.random() >= cfg["t_junction_prob"]:
            continue
        cells = [(i - 1, j), (i, j)] if t == "v" else [(i, j - 1), (i, j)]
        ends = [(i, j), (i, j + 1)] if t == "v" else [(i, j), (i + 1, j)]
        if any(c in merged for c in cells) or any(_degree(vseg, hseg, *e) <= 3 for e in ends):
            continue
        (vseg if t == "v" else hseg)[i, j] = False
        merged.update(cells)
        parent[cells[1]] = cells[0]
    faces_cells: dict[tuple[int, int], list[tuple[int, int]]] = {}
    for c in parent:
        faces_cells.setdefault(parent[c], []).append(c)
    face_of = {c: fi for fi, cs in enumerate(faces_cells.values()) for c in cs}
    faces = []
    for cs in faces_cells.values():
        i0, i1 = min(c[0] for c in cs), max(c[0] for c in cs) + 1
        j0, j1 = min(c[1] for c in cs), max(c[1] for c in cs) + 1
        faces.append((xs[i0] + hwx[i0], xs[i1] - hwx[i1], ys[j0] + hwy[j0], ys[j1] - hwy[j1]))

    # street graph -> lanes
    node_xy = np.array([(xs[i], ys[j]) for i in range(nx) for j in range(ny)])
    nid = lambda i, j: i * ny + j  # noqa: E731
    hw_node = np.array([max(hwx[i], hwy[j]) for i in range(nx) for j in range(ny)])
    reach = hw_node + curb + sw / 2  # [m] node -> middle of the crossing sidewalk
    edges = [RoadEdge(nid(i, j), nid(i, j + 1), node_xy[[nid(i, j), nid(i, j + 1)]],
                      int(lanes_x[i]), int(lanes_x[i]), _lw(lwx[i], lw), float(med_x[i]))
             for i, j in zip(*np.nonzero(vseg))]
    edges += [RoadEdge(nid(i, j), nid(i + 1, j), node_xy[[nid(i, j), nid(i + 1, j)]],
                       int(lanes_y[j]), int(lanes_y[j]), _lw(lwy[j], lw), float(med_y[j]))
              for i, j in zip(*np.nonzero(hseg))]
    kerb_r = curb + 0.5 * sw  # [m] kerb corners: painted (fillet_corners) and driven round
    rounds = pick_roundabouts(node_xy, edges, hwx.repeat(ny), np.tile(hwy, nx),
                              kerb_r, lw, cfg["roundabout_prob"], geo)
    builder = NetworkBuilder()
    degree = add_road_lanes(builder, len(node_xy), edges, reach + STOP_MARGIN, lw,
                            kerb_radius=kerb_r, roundabouts=rounds)
    u = rng.random(len(node_xy))
    p_stop, p_sig = traffic["stop_sign_prob"], traffic["signal_prob"]
    control = np.where(u < p_stop, Control.STOP, np.where(u < p_stop + p_sig, Control.SIGNAL,
                                                         Control.YIELD)).astype(np.uint8)
    control[degree <= 2] = Control.NONE
    phase = rng.uniform(0, 2 * (traffic["signal_green"] + 3.0), len(node_xy))

    # crosswalks: both sides of every street leaving a junction, between the blocks it separates
    inset = curb + sw / 2
    walk_off = min(LANE_OFFSET, sw / 4)  # walking lines stay well inside narrow sidewalks
    crossings, zebras = [], []
    for i in range(nx):
        for j in range(ny):
            n = nid(i, j)
            if degree[n] < 3:
                continue
            arms = [((0, 1), vseg, (i, j), (i - 1, j), (i, j), hwx[i]),
                    ((0, -1), vseg, (i, j - 1), (i, j - 1), (i - 1, j - 1), hwx[i]),
                    ((1, 0), hseg, (i, j), (i, j), (i, j - 1), hwy[j]),
                    ((-1, 0), hseg, (i - 1, j), (i - 1, j - 1), (i - 1, j), hwy[j])]
            for d, segs, sidx, left_cell, right_cell, hw in arms:
                if not (0 <= sidx[0] < segs.shape[0] and 0 <= sidx[1] < segs.shape[1]) \
                        or not segs[sidx]:
                    continue
                if left_cell not in face_of or right_cell not in face_of:
                    continue
                d = np.array(d, float)
                p = np.array([-d[1], d[0]])  # left of the arm's direction
                lat = hw + inset - walk_off
                for along, a, b in ((1.9, left_cell, right_cell), (3.1, right_cell, left_cell)):
                    base = node_xy[n] + d * (reach[n] + along)
                    sgn = 1.0 if a == left_cell else -1.0
                    crossings.append((face_of[a], face_of[b], base + sgn * p * lat,
                                      base - sgn * p * lat))
                zebras.append((node_xy[n] + d * (reach[n] + 2.5), d, hw))
    add_block_rings(builder, faces, inset, crossings, walk_off)
    if rounds:  # the ring's yield points are junctions of their own
        ring_xy, ring_ctl = ring_nodes(rounds)
        control[[r.node for r in rounds]] = Control.NONE
        node_xy = np.vstack([node_xy, ring_xy])
        control = np.concatenate([control, ring_ctl])
        phase = np.concatenate([phase, np.zeros(len(ring_xy))])

    # rasters
    res = cfg["resolution"]
    width, height = xs[-1] + margin, ys[-1] + margin
    shape = (int(np.ceil(height / res)), int(np.ceil(width / res)))
    # the warp (None: straight streets) is drawn here, geo's next draws either way; a
    # warped city's raster is re-sampled into a new one, so this one is scratch
    drawn = draw_warp(cfg, (width, height), geo) if geo is not None else None
    warped = drawn is not None
    raster = (scratch_raster(shape, MapClass.INTERMEDIATE) if warped
              else np.full(shape, MapClass.INTERMEDIATE, np.uint8))
    surface = np.full(shape, Surface.YARD, np.uint8)
    org = (0.0, 0.0)
    for fx0, fx1, fy0, fy1 in faces:
        fill_rect(surface, fx0, fx1, fy0, fy1, org, res, Surface.SIDEWALK)
        fill_rect(surface, fx0 + curb + sw, fx1 - curb - sw, fy0 + curb + sw, fy1 - curb - sw,
                  org, res, Surface.YARD)
    # beyond the ring road: one-sided strips of frontage facing it (bottom, right, top, left)
    x_in, x_out = xs[0] - hwx[0], xs[-1] + hwx[-1]
    y_in, y_out = ys[0] - hwy[0], ys[-1] + hwy[-1]
    strips = [((x_in, x_out, 0.0, y_in), 2), ((x_out, width, y_in, y_out), 3),
              ((x_in, x_out, y_out, height), 0), ((0.0, x_in, y_in, y_out), 1)]
    strips = [(s, side) for s, side in strips if min(s[1] - s[0], s[3] - s[2]) > curb + sw + 4]
    for box, side in strips:
        start, along, inward, length = _sides(box)[side]
        a, b = start, start + along * length + inward * (curb + sw)
        fill_rect(surface, min(a[0], b[0]), max(a[0], b[0]), min(a[1], b[1]), max(a[1], b[1]),
                  org, res, Surface.SIDEWALK)
    # a warp re-samples the rasters (a second rounding to cells): the road gets half a
    # cell more on each side first, so that no lane loses kerb clearance to rounding
    pad = 0.5 * res if warped else 0.0
    (iv, jv), (ih, jh) = np.nonzero(vseg), np.nonzero(hseg)
    roads = np.concatenate([
        np.stack([xs[iv] - hwx[iv] - pad, xs[iv] + hwx[iv] + pad, ys[jv] - hwy[jv],
                  ys[jv + 1] + hwy[jv + 1]], -1),
        np.stack([xs[ih] - hwx[ih], xs[ih + 1] + hwx[ih + 1], ys[jh] - hwy[jh] - pad,
                  ys[jh] + hwy[jh] + pad], -1)])
    fill_rects(raster, roads, org, res, MapClass.ROAD)
    fill_rects(surface, roads, org, res, Surface.ROAD)
    # the corners a shear squeezes keep the right turns' kerb clearance (warp.kerb_ease)
    ease = kerb_ease(cfg["shear_deg"], 0.5 * max(lwx.max(), lwy.max())) if pad > 0 else 0.0
    for face in faces:
        fillet_corners(raster, surface, face, kerb_r + ease, res)
    _zebras(surface, zebras, res)
    medians = [(e.poly, e.median, reach[e.u] + STOP_MARGIN, reach[e.v] + STOP_MARGIN)
               for e in edges if e.median > 0]
    for poly, wid, t_u, t_v in medians:
        a, b = median_box(poly, wid, t_u, t_v)
        for r, v in ((raster, MapClass.INTERMEDIATE), (surface, Surface.VERGE)):
            fill_rect(r, a[0], b[0], a[1], b[1], org, res, v)
    for r in rounds:
        paint_roundabout(raster, surface, r, res)
    walk_ends = np.array([p for c in crossings for p in c[2:]]).reshape(-1, 2)
    # parking strips (no vehicle across a crosswalk): every side of every block, then
    # the street side of each frontage strip
    slots, parked, spots = city_slots(list(faces) + [box for box, _ in strips],
                                      [(0, 1, 2, 3)] * len(faces) + [(s,) for _, s in strips],
                                      cfg, rng, walk_ends)
    fill_rects(surface, spots, org, res, Surface.PARKING)
    buildings = city_buildings(list(faces) + [box for box, _ in strips],
                               [-1] * len(faces) + [side for _, side in strips], cfg, rng)
    lot_slots, lot_rects = np.zeros((0, 6)), np.zeros((0, 4))
    if cfg["lot_prob"] > 0:  # a stream of their own: without lots, the city of before
        kept, lot_slots, lot_rects = city_lots(list(faces), [_sides(f) for f in faces],
                                               buildings, cfg, rng.spawn(1)[0])
        buildings = [buildings[i] for i in kept]
        fill_rects(surface, lot_rects, org, res, Surface.PARKING)
    if drawn is None:
        for b in buildings:
            for r, v in ((raster, MapClass.BUILDING), (surface, Surface.BUILDING)):
                fill_rect(r, b[:, 0].min(), b[:, 0].max(), b[:, 1].min(), b[:, 1].max(),
                          org, res, v)
    # a child stream: heights do not shift the draws of the layout and the traffic
    heights = _building_heights(len(buildings), cfg, rng.spawn(1)[0])
    has_parking = _parked_keys(faces, strips, parked)
    sides = [(*four[k], (tuple(box), k) in has_parking)
             for box, four, ks in [(f, _sides(f), range(4)) for f in faces] +
             [(box, _sides(box), (k,)) for box, k in strips] for k in ks]
    clutter = clutter or {"density": 0.0}
    parked_boxes = np.vstack([slots, lot_slots]) if len(lot_slots) else slots
    obstacles = place_clutter(sides, buildings, parked_boxes, walk_ends, curb, sw, clutter, real)
    obstacles = clear_of_lots(obstacles, lot_rects)
    if medians or rounds:
        obstacles = concat_obstacles([obstacles, island_clutter(rounds, clutter, geo),
                                      median_clutter([median_box(*m) for m in medians],
                                                     clutter, geo)])
    streets = [e.poly for e in edges]
    meta = {"kind": "procedural", "parking_slots": slots, "lot_slots": lot_slots,
            "faces": faces, "warp": None,
            "surface": surface,
            "roundabouts": np.array([[*r.centre, r.r_out, r.r_island] for r in rounds]
                                    ).reshape(-1, 4)}
    if drawn is not None:  # curved and diagonal streets: everything through one warp
        warp, (width, height) = drawn
        shape = (int(np.ceil(height / res)), int(np.ceil(width / res)))
        # the drawing-only surface is warped when first read (raster.surface_raster)
        raster = warp.raster(raster, shape, res, MapClass.INTERMEDIATE)
        warp_lanes(builder, warp)
        node_xy = warp.points(node_xy)
        buildings = [b[:-1] for b in warp.polylines([np.vstack([b, b[:1]]) for b in buildings],
                                                    BUILDING_STEP)]
        fill_polygons(raster, buildings, org, res, MapClass.BUILDING)
        slots = warp_boxes(warp, slots)
        obstacles = warp_obstacles(warp, obstacles)
        streets = warp.polylines(streets)
        meta["roundabouts"][:, :2] = warp.points(meta["roundabouts"][:, :2])
        meta.update(parking_slots=slots, lot_slots=warp_boxes(warp, lot_slots), warp=warp,
                    surface_source=meta.pop("surface"))
    network = builder.build(node_xy, control, phase, lw)
    street_lanes = np.array([e.n_fwd + e.n_bwd for e in edges], np.int64)
    return WorldMap(raster=raster, origin=org, resolution=res, buildings=buildings,
                    lanes=network, meta=meta, building_heights=heights,
                    kerb_height=cfg["kerb_height"], obstacles=obstacles, streets=streets,
                    street_lanes=street_lanes)


def _varied_geometry(cfg: dict[str, Any]) -> bool:
    """Curved streets, roundabouts or medians are on."""
    return (cfg["shear_deg"] > 0 or cfg["bend_amplitude"] > 0 or cfg["roundabout_prob"] > 0
            or cfg["median_prob"] > 0)


def _lw(w: float, default: float) -> float | None:
    return None if w == default else float(w)


def _parked_keys(faces, strips, parked) -> set[tuple[tuple[float, ...], int]]:
    """``(box, side)`` keys of the block sides that have a parking strip."""
    boxes = list(faces) + [box for box, _ in strips]
    return {(tuple(boxes[f]), k) for f, k in parked}


def _building_heights(n: int, cfg, rng: np.random.Generator) -> np.ndarray:
    """``(n,) float64`` roof heights [m]: whole storeys of ~3 m between the configured
    bounds, plus up to 1.5 m of roof."""
    lo, hi = cfg["building_height_min"], cfg["building_height_max"]
    storeys = rng.integers(max(int(lo // 3.0), 1), max(int(hi // 3.0), 1) + 1, n)
    return np.clip(storeys * 3.0 + rng.uniform(0.0, 1.5, n), lo, hi)


def _degree(vseg: np.ndarray, hseg: np.ndarray, i: int, j: int) -> int:
    nx, ny = vseg.shape[0], hseg.shape[1]
    return int(sum([j < ny - 1 and vseg[i, j], j > 0 and vseg[i, j - 1],
                    i < nx - 1 and hseg[i, j], i > 0 and hseg[i - 1, j]]))


def _zebras(surface, zebras, res):
    """Paint zebra crossings 3 m wide across streets (drawing only): ``zebras`` is a list
    of ``(centre (2,), direction along the street (2,), street half width)``; one
    stripe per metre, all stripes of all crossings in one call, in order."""
    if not zebras:
        return
    ks = [np.arange(-hw + 0.25, hw, 1.0) for _, _, hw in zebras]
    n = [len(k) for k in ks]
    k = np.concatenate(ks)[:, None]
    centre = np.repeat(np.array([z[0] for z in zebras], np.float64), n, axis=0)
    d = np.repeat(np.array([z[1] for z in zebras], np.float64), n, axis=0)
    p = np.stack([-d[:, 1], d[:, 0]], -1)
    a = centre + p * k - d * 1.5
    b = centre + p * (k + 0.5) + d * 1.5
    fill_rects(surface, np.stack([np.minimum(a[:, 0], b[:, 0]), np.maximum(a[:, 0], b[:, 0]),
                                  np.minimum(a[:, 1], b[:, 1]), np.maximum(a[:, 1], b[:, 1])], -1),
               (0.0, 0.0), res, Surface.CROSSWALK)


def _sides(face):
    """The four sides of a block: (start, direction along, inward normal, length)."""
    x0, x1, y0, y1 = face
    return [(np.array([x0, y0]), np.array([1.0, 0]), np.array([0, 1.0]), x1 - x0),
            (np.array([x1, y0]), np.array([0, 1.0]), np.array([-1.0, 0]), y1 - y0),
            (np.array([x1, y1]), np.array([-1.0, 0]), np.array([0, -1.0]), x1 - x0),
            (np.array([x0, y1]), np.array([0, -1.0]), np.array([1.0, 0]), y1 - y0)]
