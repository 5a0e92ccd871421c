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

import bz2
import math
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import numpy as np
import shapely
from shapely.geometry import LineString, Polygon

from dstenv.sim.lanes import Control, LaneKind, NetworkBuilder, cut_polyline, offset_polyline
from dstenv.sim.raster import Surface, fill_polygon
from dstenv.sim.roads import RoadEdge, add_road_lanes, turning_circle
from dstenv.sim.types import DEFAULT_BUILDING_HEIGHT, MapClass, WorldMap

__all__ = ["load_osm", "latlon_to_mercator", "EARTH_RADIUS", "OSM_LIMITS"]

EARTH_RADIUS = 6378137.0  # [m] as in the KITTI devkit
#: total lanes assumed per vehicle road type when untagged
ROAD_LANES = {"motorway": 4, "trunk": 4, "primary": 2, "secondary": 2, "tertiary": 2,
              "unclassified": 2, "residential": 2, "living_street": 2, "road": 2, "busway": 2,
              "service": 2, "track": 1}
FOOT_TYPES = {"footway", "path", "pedestrian", "steps", "cycleway", "bridleway", "corridor"}
FOOT_WIDTH = 2.0  # [m]
WALK_OFFSET = 0.6  # [m] half distance between the two walking lines of a footway
KERB_RADIUS = 4.0  # [m] rounding of the kerb at junctions
STOREY_HEIGHT = 3.0  # [m] per ``building:levels`` level


def latlon_to_mercator(lat, lon, scale: float) -> tuple[np.ndarray, np.ndarray]:
    """KITTI devkit ``latlonToMercator``: ``(mx, my)`` [m] of degrees ``lat``, ``lon``."""
    lat, lon = np.asarray(lat, np.float64), np.asarray(lon, np.float64)
    mx = scale * lon * math.pi * EARTH_RADIUS / 180.0
    my = scale * EARTH_RADIUS * np.log(np.tan((90.0 + lat) * math.pi / 360.0))
    return mx, my


#: limits on what an OSM file may ask of this machine (a 1 KB ``.bz2`` can inflate to
#: gigabytes, a ``<bounds>`` element can span the globe, a tag can claim 1e9 lanes)
OSM_LIMITS = {
    "bytes": 1 << 30,  # [B] decompressed XML read at most
    "nodes": 5_000_000,
    "ways": 1_000_000,
    "extent": 20_000.0,  # [m] side of the mapped area at most
    "raster_cells": 200_000_000,  # map raster cells at most (200 MB of uint8)
    "lanes": 8,  # lanes of one way at most (larger tags are clamped)
    "width": 60.0,  # [m] road width at most (larger tags are clamped)
}


class _GuardedStream:
    """A binary stream that stops past ``OSM_LIMITS["bytes"]`` and refuses DTDs.

    A document type declaration is the door to entity expansion ("billion laughs")
    and external entities; OSM files never have one, so any ``<!DOCTYPE`` or
    ``<!ENTITY`` is rejected before the XML parser sees it, whatever expat's version.
    """

    _BAD = (b"<!DOCTYPE", b"<!ENTITY")

    def __init__(self, raw: Any, path: Path) -> None:
        self.raw, self.path, self.total, self.tail = raw, path, 0, b""

    def read(self, n: int = -1) -> bytes:
        data = self.raw.read(n if n and n > 0 else 1 << 16)
        self.total += len(data)
        if self.total > OSM_LIMITS["bytes"]:
            raise ValueError(f"{self.path}: more than {OSM_LIMITS['bytes'] >> 20} MiB of XML "
                             "(decompressed); cut a smaller extract")
        window = (self.tail + data).upper()
        if any(bad in window for bad in self._BAD):
            raise ValueError(f"{self.path}: XML with a DTD or entity declaration; OSM files "
                             "have none, so it is refused")
        self.tail = window[-16:]
        return data

    def __enter__(self) -> "_GuardedStream":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.raw.close()


def _parse(path: Path) -> tuple[dict, list, list, tuple | None]:
    """Stream the XML: nodes ``{id: (lat, lon)}``, ways ``[(refs, tags)]``, building
    relations ``[([(way id, role)], tags)]``, bounds."""
    nodes: dict[int, tuple[float, float]] = {}
    ways, rels, bounds = [], [], None
    opener = bz2.open if path.suffix == ".bz2" else open
    try:
        with _GuardedStream(opener(path, "rb"), path) as fh:
            for _, el in ET.iterparse(fh, events=("end",)):
                tag = el.tag
                if tag == "node":
                    nodes[int(el.get("id"))] = (float(el.get("lat")), float(el.get("lon")))
                    if len(nodes) > OSM_LIMITS["nodes"]:
                        raise ValueError(f"{path}: more than {OSM_LIMITS['nodes']} nodes; "
                                         "cut a smaller extract")
                elif tag == "way":
                    tags = {t.get("k"): t.get("v") for t in el.iter("tag")}
                    if "building" in tags or "highway" in tags:
                        refs = [int(n.get("ref")) for n in el.iter("nd")]
                        ways.append((int(el.get("id")), refs, tags))
                        if len(ways) > OSM_LIMITS["ways"]:
                            raise ValueError(f"{path}: more than {OSM_LIMITS['ways']} "
                                             "building/road ways; cut a smaller extract")
                elif tag == "relation":
                    tags = {t.get("k"): t.get("v") for t in el.iter("tag")}
                    if "building" in tags and tags.get("type") == "multipolygon":
                        members = [(int(m.get("ref")), m.get("role")) for m in el.iter("member")
                                   if m.get("type") == "way"]
                        rels.append((members, tags))
                elif tag == "bounds":
                    bounds = tuple(float(el.get(k))
                                   for k in ("minlat", "minlon", "maxlat", "maxlon"))
                if tag in ("node", "way", "relation"):
                    el.clear()
    except ET.ParseError as exc:
        raise ValueError(f"{path}: malformed OSM XML: {exc}") from None
    except (OSError, EOFError) as exc:
        if isinstance(exc, FileNotFoundError):
            raise FileNotFoundError(f"{path}: OSM file not found") from None
        raise ValueError(f"{path}: cannot read OSM file: {exc}") from None
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{path}: invalid OSM element: {exc}") from None
    return nodes, ways, rels, bounds


def _width(tags: dict[str, str], lane_width: float) -> tuple[float, int, int]:
    """Road width [m] and lanes forward / backward of a vehicle way."""
    kind = tags["highway"].removesuffix("_link")
    oneway = tags.get("oneway", "no") in ("yes", "true", "1", "-1") or kind == "motorway" \
        or tags.get("junction") == "roundabout"
    try:
        total = int(min(max(float(tags["lanes"]), 1.0), OSM_LIMITS["lanes"]))
    except (KeyError, ValueError, OverflowError):
        total = max(ROAD_LANES.get(kind, 2) // (2 if oneway else 1), 1)
    if oneway:
        fwd, bwd = total, 0
    else:
        fwd = _int(tags.get("lanes:forward"), max((total + 1) // 2, 1))
        bwd = _int(tags.get("lanes:backward"), max(total - fwd, 1))
    fwd, bwd = min(fwd, OSM_LIMITS["lanes"]), min(bwd, OSM_LIMITS["lanes"])
    try:
        width = float(tags["width"].replace("m", "").strip())
    except (KeyError, ValueError):
        width = (fwd + bwd) * lane_width
    if not math.isfinite(width):
        width = (fwd + bwd) * lane_width
    return float(np.clip(width, 2.0, OSM_LIMITS["width"])), fwd, bwd


def building_height(tags: dict[str, str]) -> float:
    """Roof height of an OSM building [m]: its ``height`` tag, else ``building:levels``
    x :data:`STOREY_HEIGHT` (+ ``roof:levels``), else :data:`DEFAULT_BUILDING_HEIGHT`."""
    try:
        return max(float(tags["height"].replace("m", "").strip()), 2.0)
    except (KeyError, ValueError):
        pass
    try:
        levels = float(tags["building:levels"]) + float(tags.get("roof:levels", 0))
        return max(levels * STOREY_HEIGHT, 2.0)
    except (KeyError, ValueError):
        return DEFAULT_BUILDING_HEIGHT


def _int(text: str | None, default: int) -> int:
    try:
        return max(int(text), 1) if text is not None else default
    except ValueError:
        return default


def _check_extent(path: Path, width: float, height: float, margin: float,
                  resolution: float) -> None:
    """Refuse a map whose area or raster would not fit (named, with the numbers)."""
    side = max(width, height)
    if not math.isfinite(side) or side > OSM_LIMITS["extent"]:
        raise ValueError(f"{path}: the map spans {side / 1000:.1f} km (its <bounds> or nodes); "
                         f"at most {OSM_LIMITS['extent'] / 1000:g} km is supported")
    cells = ((width + 2 * margin) / resolution) * ((height + 2 * margin) / resolution)
    if cells > OSM_LIMITS["raster_cells"]:
        raise ValueError(f"{path}: a {resolution:g} m raster of this map needs {cells:.3g} cells "
                         f"(more than {OSM_LIMITS['raster_cells']:.3g}); use a coarser "
                         "world.map.resolution or a smaller extract")


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
    nodes, ways, rels, bounds = _parse(path)
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
    _check_extent(path, bx1 - bx0, by1 - by0, margin, resolution)
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
                width, fwd, bwd = _width(tags, lane_width)
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
