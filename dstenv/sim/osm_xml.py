"""OpenStreetMap XML reading: a guarded streaming parser, the devkit's Mercator
projection and the tag rules (road width and lanes, building height).

:func:`parse_osm` refuses what a hostile file could ask of the machine
(:data:`OSM_LIMITS`: decompressed size, element counts, DTDs); :mod:`dstenv.sim.osm`
builds the :class:`~dstenv.sim.types.WorldMap` from what it returns.
"""

from __future__ import annotations

import bz2
import math
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import numpy as np

from dstenv.sim.types import DEFAULT_BUILDING_HEIGHT

__all__ = ["EARTH_RADIUS", "OSM_LIMITS", "building_height", "check_extent", "latlon_to_mercator",
           "parse_osm", "road_width"]

EARTH_RADIUS = 6378137.0  # [m] as in the KITTI devkit
#: total lanes assumed per vehicle road type when untagged
ROAD_LANES = {"motorway": 4, "trunk": 4, "primary": 2, "secondary": 2, "tertiary": 2,
              "unclassified": 2, "residential": 2, "living_street": 2, "road": 2, "busway": 2,
              "service": 2, "track": 1}
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


def parse_osm(path: Path) -> tuple[dict, list, list, tuple | None]:
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
                    lat, lon = float(el.get("lat")), float(el.get("lon"))
                    if not (abs(lat) < 90.0 and abs(lon) <= 180.0):  # NaN fails too
                        raise ValueError(f"node {el.get('id')}: lat, lon = {lat}, {lon} are "
                                         "not coordinates in degrees")
                    nodes[int(el.get("id"))] = (lat, lon)
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
        if str(exc).startswith(f"{path}: "):  # our own check, naming the file already
            raise ValueError(str(exc)) from None
        raise ValueError(f"{path}: invalid OSM element: {exc}") from None
    return nodes, ways, rels, bounds


def road_width(tags: dict[str, str], lane_width: float) -> tuple[float, int, int]:
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


def check_extent(path: Path, width: float, height: float, margin: float,
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
