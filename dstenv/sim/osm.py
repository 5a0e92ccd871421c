"""OpenStreetMap XML (``.osm``, ``.osm.bz2``) -> :class:`WorldMap` with a lane network.

* ``building=*`` ways (and outer ways of building multipolygons) -> building polygons;
* ``highway=*`` ways for vehicles -> road, widened by ``width`` [m] or ``lanes``
  (x lane width) or a default per road type; lanes for routing on both sides
  (``oneway`` respected), connected at shared nodes;
* footways, paths, steps, cycleways -> intermediate space walked by pedestrians;
* everything else -> intermediate.

Coordinates use the KITTI devkit's Mercator convention: with
``scale = cos(lat0 * pi / 180)`` and ``R = 6378137``,
``mx = scale * lon * pi * R / 180`` and ``my = scale * R * log(tan((90 + lat) * pi / 360))``;
world ``(x, y) = (mx, my) - meta["mercator_offset"]`` where the offset is the Mercator
position of ``meta["latlon_origin"] = (lat0, lon0)``, the centre of the extract.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import shapely
from shapely.geometry import LineString, Polygon

from dstenv.sim.lanes import Control, LaneKind, NetworkBuilder, cut_polyline, offset_polyline
from dstenv.sim.raster import Surface, fill_polygon
from dstenv.sim.roads import RoadEdge, add_road_lanes, turning_circle
from dstenv.sim.osm_xml import (
    ROAD_LANES,
    building_height,
    check_extent,
    latlon_to_mercator,
    parse_osm,
    road_width,
)
from dstenv.sim.types import MapClass, WorldMap

__all__ = ["check_osm_file", "load_osm", "resolve_osm_file"]

FOOT_TYPES = {"footway", "path", "pedestrian", "steps", "cycleway", "bridleway", "corridor"}
FOOT_WIDTH = 2.0  # [m]
WALK_OFFSET = 0.6  # [m] half distance between the two walking lines of a footway
KERB_RADIUS = 4.0  # [m] rounding of the kerb at junctions


def check_osm_file(map_cfg: Mapping[str, Any], base_dir: str | Path | None = None) -> None:
    """Before any world exists: the file of a ``world.map.kind = "osm"`` section must
    exist (else the first reset, in every env of a vector env, found out).

    Raises:
        ConfigError: no such file, named with where it was looked for.
    """
    from dstenv.config import ConfigError

    if map_cfg.get("kind") != "osm":
        return
    path = resolve_osm_file(str(map_cfg.get("osm_file", "")), base_dir)
    if path.is_dir():
        raise ConfigError(f"world.map.osm_file {map_cfg['osm_file']!r}: {path} is a folder; "
                          "give the .osm or .osm.bz2 file in it")
    if not path.is_file():
        raise ConfigError(f"world.map.osm_file {map_cfg['osm_file']!r}: no such file ({path}); "
                          "give it absolute, beside the scenario file, or in the current "
                          "folder")


def resolve_osm_file(name: str, base_dir: str | Path | None = None) -> Path:
    """Where ``world.map.osm_file`` points: an absolute path as is; a relative one looked
    up in ``base_dir`` (a scenario's folder), the current folder, then the shipped
    scenarios. Returns the first existing candidate, else the first candidate (the
    caller's error names it).

    Raises:
        ConfigError: ``name`` is empty.
    """
    from importlib import resources

    from dstenv.config import ConfigError

    if not name:
        raise ConfigError("world.map.osm_file: required when world.map.kind = 'osm'")
    path = Path(name)
    if path.is_absolute():
        return path
    bases = [Path(base_dir)] if base_dir is not None else []
    bases += [Path.cwd(), Path(str(resources.files("dstenv.scenarios")))]
    return next((b / path for b in bases if (b / path).is_file()), bases[0] / path)


def load_osm(path: str | Path, *, resolution: float = 0.2, lane_width: float = 3.0,
             margin: float = 12.0, traffic: dict[str, Any] | None = None) -> WorldMap:
    """Load an OpenStreetMap extract into a map with lanes.

    Ways that reference nodes missing from the file are clipped to the nodes
    present (a way left with too few nodes is dropped); ``meta["clipped_ways"]``
    and ``meta["dropped_ways"]`` count them.

    Args:
        path: ``.osm`` or ``.osm.bz2`` file.
        resolution: raster cell size [m].
        lane_width: lane width of ways without a ``width`` tag [m].
        margin: free space around the extract [m].
        traffic: the world's ``traffic`` config (junction-control shares); None: yield.

    Returns:
        A :class:`WorldMap`; ``meta`` holds ``latlon_origin`` (deg), ``mercator_scale``,
        ``mercator_offset`` ([m], Mercator of the origin), ``surface``, ``osm_file``.

    Raises:
        FileNotFoundError, ValueError: unreadable or malformed file (one line naming it).
    """
    path = Path(path)
    nodes, ways, rels, bounds = parse_osm(path)
    if bounds is None:
        if not nodes:
            raise ValueError(f"{path}: no nodes in OSM file")
        lat_lon = np.array(list(nodes.values()))
        bounds = (*lat_lon.min(0), *lat_lon.max(0))
    lat0, lon0 = (bounds[0] + bounds[2]) / 2, (bounds[1] + bounds[3]) / 2
    scale = math.cos(math.radians(lat0))
    mx0, my0 = latlon_to_mercator(lat0, lon0, scale)

    ids = np.fromiter(nodes.keys(), np.int64, len(nodes))
    ll = np.array(list(nodes.values()), np.float64).reshape(-1, 2)
    mx, my = latlon_to_mercator(ll[:, 0], ll[:, 1], scale)
    pos = dict(zip(ids.tolist(), np.stack([mx - mx0, my - my0], -1)))
    corners = np.stack(latlon_to_mercator([bounds[0], bounds[2]], [bounds[1], bounds[3]], scale),
                       -1) - [mx0, my0]
    (bx0, by0), (bx1, by1) = corners
    check_extent(path, bx1 - bx0, by1 - by0, margin, resolution)
    box = shapely.box(bx0, by0, bx1, by1)

    def project(refs: list[int]) -> np.ndarray:
        return np.array([pos[r] for r in refs], np.float64).reshape(-1, 2)

    clipped = dropped = 0
    by_id: dict[int, list[int]] = {}
    roads, foot, buildings = [], [], []
    heights: list[float] = []
    for wid, refs, tags in ways:
        kept = [r for r in refs if r in nodes]
        kept = [r for i, r in enumerate(kept) if i == 0 or r != kept[i - 1]]
        clipped += len(kept) < len(refs)
        by_id[wid] = kept
        if "building" in tags and tags["building"] != "no":
            if len(kept) >= 3:
                buildings.append(Polygon(project(kept)))
                heights.append(building_height(tags))
            else:
                dropped += 1
        elif "highway" in tags:
            kind = tags["highway"].removesuffix("_link")
            if len(kept) < 2:
                dropped += 1
            elif kind in ROAD_LANES or tags["highway"].endswith("_link"):
                refs2 = kept[::-1] if tags.get("oneway") == "-1" else kept
                width, fwd, bwd = road_width(tags, lane_width)
                for run in _inside_runs(refs2, pos, box):
                    roads.append((run, width, fwd, bwd))
            elif kind in FOOT_TYPES:
                line = LineString(project(kept)).intersection(box)
                foot += [np.asarray(g.coords) for g in getattr(line, "geoms", [line])
                         if isinstance(g, LineString) and not g.is_empty]
    for members, rel_tags in rels:
        for ref, role in members:
            if role == "outer" and len(by_id.get(ref, [])) >= 3:
                buildings.append(Polygon(project(by_id[ref])))
                heights.append(building_height(rel_tags))
    buildings = [(b.buffer(0) if not b.is_valid else b).intersection(box) for b in buildings]

    # street graph: split vehicle ways at shared nodes and at their ends
    use: dict[int, int] = {}
    for refs, *_ in roads:
        for r in refs:
            use[r] = use.get(r, 0) + 1
    gid: dict[int, int] = {}
    edges: list[RoadEdge] = []
    half: dict[int, float] = {}
    edge_half: list[float] = []
    for refs, width, fwd, bwd in roads:
        cuts = [0] + [i for i in range(1, len(refs) - 1) if use[refs[i]] > 1] + [len(refs) - 1]
        if refs[0] == refs[-1] and len(cuts) == 2:  # closed loop without junction
            cuts.insert(1, len(refs) // 2)
        for a, b in zip(cuts[:-1], cuts[1:]):
            ends = [gid.setdefault(refs[a], len(gid)), gid.setdefault(refs[b], len(gid))]
            poly = project(refs[a:b + 1])
            if ends[0] == ends[1] or np.hypot(*np.diff(poly, axis=0).T).sum() < 1.0:
                continue
            lw = float(np.clip(width / (fwd + bwd), 2.5, 4.0))
            edges.append(RoadEdge(ends[0], ends[1], poly, fwd, bwd, lw))
            edge_half.append(width / 2)
            for n in ends:
                half[n] = max(half.get(n, 0.0), width / 2)
    if not edges:  # (the lane network of nothing crashed numba: a segfault)
        raise ValueError(f"{path}: no drivable road in the OSM file (a highway way of at "
                         "least 1 m between two distinct nodes, inside the map's area)")
    node_xy = np.zeros((len(gid), 2))
    for ref, n in gid.items():
        node_xy[n] = pos[ref]
    trims = np.array([half.get(n, 3.0) + 1.5 for n in range(len(gid))])
    builder = NetworkBuilder()
    degree = add_road_lanes(builder, len(gid), edges, trims, lane_width,
                            kerb_radius=KERB_RADIUS)
    rng = np.random.default_rng(0)  # fixed: the same file gives the same junction rules
    tr = traffic or {"stop_sign_prob": 0.0, "signal_prob": 0.0, "signal_green": 12.0}
    u = rng.random(len(gid))
    control = np.where(u < tr["stop_sign_prob"], Control.STOP,
                       np.where(u < tr["stop_sign_prob"] + tr["signal_prob"], Control.SIGNAL,
                                Control.YIELD)).astype(np.uint8)
    control[degree <= 2] = Control.NONE
    phase = rng.uniform(0, 2 * (tr["signal_green"] + 3.0), len(gid))

    # rasters: roads win over (erroneously) overlapping buildings, so lanes stay clear
    # rasters over the extract's bounds; roads win over (erroneously) overlapping buildings
    origin = (float(bx0 - margin), float(by0 - margin))
    shape = (int(np.ceil((by1 - by0 + 2 * margin) / resolution)),
             int(np.ceil((bx1 - bx0 + 2 * margin) / resolution)))
    raster = np.full(shape, MapClass.INTERMEDIATE, np.uint8)
    surface = np.full(shape, Surface.YARD, np.uint8)
    road_polys = [LineString(e.poly).buffer(h, cap_style="round", join_style="round")
                  for e, h in zip(edges, edge_half)]
    for line in foot:
        _paint(surface, LineString(line).buffer(FOOT_WIDTH / 2), origin, resolution,
               Surface.SIDEWALK)
    for e in edges:  # paved turning circles where streets end
        for n, seg in ((e.u, e.poly[[1, 0]]), (e.v, e.poly[[-2, -1]])):
            if degree[n] == 1:
                d = seg[1] - seg[0]
                centre, radius = turning_circle(node_xy[n], float(np.arctan2(d[1], d[0])), 3.0)
                road_polys.append(shapely.Point(centre).buffer(radius))
    road_union = shapely.union_all(road_polys) if road_polys else Polygon()
    # rounded kerbs at junctions (a morphological closing), so turning cars stay on road
    road_union = road_union.buffer(KERB_RADIUS).buffer(-KERB_RADIUS)
    polys, poly_heights = [], []
    for b, bh in zip(buildings, heights):
        if b.intersects(road_union):
            b = b.difference(road_union)
        for part in getattr(b, "geoms", [b]):
            if isinstance(part, Polygon) and part.area > 1.0:
                polys.append(np.asarray(part.exterior.coords)[:-1])
                poly_heights.append(bh)
                _paint(raster, part, origin, resolution, MapClass.BUILDING)
                _paint(surface, part, origin, resolution, Surface.BUILDING)
    _paint(raster, road_union, origin, resolution, MapClass.ROAD)
    _paint(surface, road_union, origin, resolution, Surface.ROAD)
    wm = WorldMap(raster=raster, origin=origin, resolution=resolution, buildings=polys,
                  building_heights=np.array(poly_heights, np.float64))
    _add_walks(builder, wm, edges, edge_half, trims, foot)
    wm.lanes = builder.build(node_xy, control, phase, lane_width)
    wm.streets = [np.asarray(e.poly, np.float64) for e in edges]
    wm.street_lanes = np.array([e.n_fwd + e.n_bwd for e in edges], np.int64)
    wm.meta = {"kind": "osm", "osm_file": str(path), "latlon_origin": (lat0, lon0),
               "mercator_scale": scale, "mercator_offset": (float(mx0), float(my0)),
               "surface": surface, "clipped_ways": int(clipped), "dropped_ways": int(dropped),
               "street_half_widths": np.array(edge_half, np.float64)}
    return wm


def _inside_runs(refs: list[int], pos: dict, box: Any) -> list[list[int]]:
    """Pieces of a way inside ``box``. A piece that leaves the box ends exactly on its
    edge, at a new node (negative id, position added to ``pos``)."""
    inside = [bool(box.covers(shapely.Point(pos[r]))) for r in refs]
    n, runs, k = len(refs), [], 0
    while k < n:
        if not inside[k] and not (k + 1 < n and inside[k + 1]):
            k += 1
            continue
        j = k + 1
        while j < n and inside[j]:
            j += 1
        end = min(j, n - 1)
        run = list(refs[k:end + 1])
        for e, nxt in ((0, 1), (len(run) - 1, len(run) - 2)):
            if not inside[k + e]:
                a = np.asarray(pos[run[nxt]])
                cut = np.asarray(LineString([a, pos[run[e]]]).intersection(box).coords)
                new = -(len(pos) + 1)
                pos[new] = cut[np.argmax(np.hypot(*(cut - a).T))]
                run[e] = new
        if len(run) >= 2:
            runs.append(run)
        k = j
    return runs


def _paint(raster: np.ndarray, geom: Any, origin, res: float, value: int) -> None:
    for part in getattr(geom, "geoms", [geom]):
        if isinstance(part, Polygon) and not part.is_empty:
            rings = [np.asarray(part.exterior.coords)]
            rings += [np.asarray(r.coords) for r in part.interiors]
            fill_polygon(raster, rings, origin, res, value)


def _add_walks(builder: NetworkBuilder, wm: WorldMap, edges: list[RoadEdge],
               edge_half: list[float], trims: np.ndarray, foot: list[np.ndarray]) -> None:
    """Pedestrian lanes beside roads and on footways, where the map is intermediate.

    Each walk is a pair of opposite lanes 1.2 m apart joined at both ends, so
    pedestrians walk to the end, turn round and come back.
    """
    from dstenv.sim.raster import lookup

    lines = []
    for e, half in zip(edges, edge_half):
        total = float(np.hypot(*np.diff(e.poly, axis=0).T).sum())
        s0, s1 = trims[e.u] + 2.0, total - trims[e.v] - 2.0
        if s1 - s0 < 8.0:
            continue
        centre = cut_polyline(e.poly, s0, s1)
        for side in (1.0, -1.0):
            lines.append(offset_polyline(centre, side * (half + 1.6)))
    lines += [f for f in foot if np.hypot(*np.diff(f, axis=0).T).sum() >= 8.0]
    for line in lines:
        a = offset_polyline(line, -WALK_OFFSET)
        b = offset_polyline(line, WALK_OFFSET)[::-1]
        dense = np.vstack([np.linspace(p, q, 6) for p, q in zip(np.vstack([a, b])[:-1],
                                                                 np.vstack([a, b])[1:])])
        if not (lookup(wm, dense) == MapClass.INTERMEDIATE).all():
            continue
        la, lb = builder.add(a, LaneKind.SIDEWALK), builder.add(b, LaneKind.SIDEWALK)
        ta = builder.add(np.stack([a[-1], b[0]]), LaneKind.SIDEWALK)
        tb = builder.add(np.stack([b[-1], a[0]]), LaneKind.SIDEWALK)
        builder.link(la, ta), builder.link(ta, lb), builder.link(lb, tb), builder.link(tb, la)
