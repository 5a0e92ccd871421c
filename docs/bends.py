"""Do cars that follow their lane stay on the painted road in junctions? (issue 17)

For every connector lane of many maps (procedural scenarios ``default``, ``dense``,
``suburb``, seeds ``0..N-1``, plus the OSM maps; ``occluded``, the occlusion task's
world, changes only buildings, so its roads and lanes are the default's: same
figures), the lane centre is sampled every 0.25 m and an ego-sized box (4.5 x 1.9 m) is
put there with the lane's heading. A box *leaves the road* when a point of its
outline (every 0.1 m) lies on a raster cell that is not ``MapClass.ROAD``; its
*overlap* [m] is how far that point lies beyond the painted edge and its *clearance*
[m] the smallest distance of the outline to it (both from a distance transform of the
ROAD cells, edge half-way between cell centres). Connectors are grouped by kind:
right, left, straight, U-turn and roundabout ring pieces (entries and exits included).
``env15`` counts connectors where the env's own 15-point off-road rule
(:func:`dstenv.sim.ego.hits`) fires.

``--pursuit`` also drives the ego by autopilot (no traffic) through right-turn
connectors: the ego starts 20 m before the stop line at 6 m/s; its largest lateral
offset from the lane centre towards the kerb (to the right) on the connector and
whether the world flags it ``off_road`` there are reported (the pursuit rule's corner
cutting).

    python docs/bends.py --seeds 50 --out docs/bends-after.json
    python docs/bends.py --seeds 10 --pursuit 40    # + 40 driven right turns per scenario

JSON out (stdout, and ``--out``): per scenario and connector kind the number of
connectors, the share that leaves the road, the worst overlap [m], the 1st percentile
of the clearance [m], and the env15 share.

Measured 2026-12-02 (docs/realism.md, "Right-turn bends"; ``--seeds 50 --pursuit
40``): right turns leaving the road, default 1.19 % (worst 0.72 m) -> 0, dense 6.06 %
(0.90 m) -> 0, suburb 0.07 % -> 0; driven right turns off the road 1 / 3 / 0 of 40 ->
0 / 0 / 0 (the ego cuts <= 0.19 m towards the kerb, before and after).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np
from scipy.ndimage import distance_transform_edt

from dstenv.config import section
from dstenv.scenario_files import load_scenario
from dstenv.sim import World
from dstenv.sim.citygen import generate_city
from dstenv.sim.lanes import LaneKind, Turn
from dstenv.sim.types import MapClass, WorldMap

KINDS = ("right", "left", "straight", "uturn", "ring")
STEP = 0.25  # [m] between box positions along a lane
OUTLINE = 0.1  # [m] between outline points of the box
LENGTH, WIDTH = 4.5, 1.9  # [m] the ego (world.ego defaults)
SHARED = Path(os.environ.get("DSTENV_SHARED_DATA",  # ../shared/data beside the checkout
                             Path(__file__).resolve().parents[2] / "shared" / "data"))
OSM = [Path(__file__).resolve().parents[1] / "dstenv/scenarios/small-town.osm",
       SHARED / "osm/kirchberg-small.osm", SHARED / "osm/west-oakland.osm.bz2"]


def world_config(name: str) -> dict:
    """The validated ``world`` section of a shipped scenario (``occluded``: the
    occlusion task's world on top of the defaults)."""
    if name == "occluded":
        from dstenv.envs.registration import OCCLUDED_WORLD
        return section("world", OCCLUDED_WORLD)
    return section("world", load_scenario(name).get("world", {}))


def signed_distance(world_map: WorldMap) -> np.ndarray:
    """``(Hm, Wm) float32`` [m]: distance of each cell centre to the painted road edge
    (half-way between a ROAD and a non-ROAD cell), positive on ROAD cells."""
    road = world_map.raster == MapClass.ROAD
    res = world_map.resolution
    inside = distance_transform_edt(road) * res
    outside = distance_transform_edt(~road) * res
    return np.where(road, inside - res / 2, -(outside - res / 2)).astype(np.float32)


def connector_kinds(world_map: WorldMap) -> tuple[np.ndarray, np.ndarray]:
    """Vehicle connectors of a map and their kind: ``(C,) int64`` lane ids and
    ``(C,) <U8`` names from :data:`KINDS` (``ring``: a roundabout's pieces, entries
    and exits)."""
    net = world_map.lanes
    lanes = np.flatnonzero(net.kind == LaneKind.CONNECTOR)
    names = np.array([("straight", "left", "right", "uturn")[t] for t in net.turn[lanes]],
                     dtype="<U8")
    rounds = np.asarray(world_map.meta.get("roundabouts", np.zeros((0, 4)))).reshape(-1, 4)
    for cx, cy, r_out, _ in rounds:
        d = np.hypot(net.node_xy[net.node[lanes], 0] - cx, net.node_xy[net.node[lanes], 1] - cy)
        names[d < r_out + 1.0] = "ring"
    return lanes, names


def lane_samples(world_map: WorldMap, lanes: np.ndarray, step: float = STEP
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Poses every ``step`` [m] along ``lanes`` (both ends included), as
    :func:`~dstenv.sim.lanes.lane_pose` gives them: ``xy (M, 2)``, ``yaw (M,)`` and
    ``owner (M,) int64`` (index into ``lanes``)."""
    net = world_map.lanes
    counts = np.ceil(net.length[lanes] / step).astype(np.int64) + 1
    owner = np.repeat(np.arange(len(lanes)), counts)
    first = np.concatenate([[0], np.cumsum(counts)[:-1]])
    s = np.minimum((np.arange(owner.size) - first[owner]) * step, net.length[lanes][owner])
    lane = lanes[owner]
    f = s / net.ds[lane]
    i = np.clip(np.floor(f).astype(np.int64), 0, net.npts[lane] - 2)
    t = np.clip(f - i, 0.0, 1.0)
    p = net.start[lane] + i
    xy = net.pts[p] + t[:, None] * (net.pts[p + 1] - net.pts[p])
    return xy, net.hdg[p], owner


def box_points(length: float = LENGTH, width: float = WIDTH, spacing: float = OUTLINE
               ) -> np.ndarray:
    """Outline of a box centred at 0 heading +x, a point every <= ``spacing`` [m]:
    ``(K, 2) float64``."""
    nu, nv = int(np.ceil(length / spacing)) + 1, int(np.ceil(width / spacing)) + 1
    u, v = np.linspace(-length / 2, length / 2, nu), np.linspace(-width / 2, width / 2, nv)
    return np.vstack([np.stack([u, np.full(nu, -width / 2)], -1),
                      np.stack([u, np.full(nu, width / 2)], -1),
                      np.stack([np.full(nv, -length / 2), v], -1),
                      np.stack([np.full(nv, length / 2), v], -1)])


def env_points(length: float = LENGTH, width: float = WIDTH) -> np.ndarray:
    """The 15 points of the env's off-road rule (:func:`dstenv.sim.ego.hits`)."""
    return np.array([(a * length / 2, b * width / 2) for a in (-1.0, -0.5, 0.0, 0.5, 1.0)
                     for b in (-1.0, 0.0, 1.0)])


def _lookup(field: np.ndarray, world_map: WorldMap, xy: np.ndarray, fill: float) -> np.ndarray:
    res, (x0, y0) = world_map.resolution, world_map.origin
    col = np.floor((xy[..., 0] - x0) / res).astype(np.int64)
    row = np.floor((xy[..., 1] - y0) / res).astype(np.int64)
    ok = (row >= 0) & (row < field.shape[0]) & (col >= 0) & (col < field.shape[1])
    out = np.full(xy.shape[:-1], fill, field.dtype)
    out[ok] = field[row[ok], col[ok]]
    return out


def swept_margin(world_map: WorldMap, sdist: np.ndarray, lanes: np.ndarray,
                 chunk: int = 4096) -> tuple[np.ndarray, np.ndarray]:
    """For each lane: the smallest signed distance [m] of the swept box outline to the
    painted road edge (< 0: it leaves the road by that much) and whether the env's
    15-point rule fires somewhere: ``(L,) float64``, ``(L,) bool``."""
    xy, yaw, owner = lane_samples(world_map, lanes)
    margin = np.full(len(lanes), np.inf)
    env_off = np.zeros(len(lanes), bool)
    road = (world_map.raster == MapClass.ROAD).astype(np.uint8)
    for pts, rule in ((box_points(), "outline"), (env_points(), "env")):
        for a in range(0, len(xy), chunk):
            c, s = np.cos(yaw[a:a + chunk]), np.sin(yaw[a:a + chunk])
            wx = xy[a:a + chunk, None, 0] + c[:, None] * pts[:, 0] - s[:, None] * pts[:, 1]
            wy = xy[a:a + chunk, None, 1] + s[:, None] * pts[:, 0] + c[:, None] * pts[:, 1]
            w = np.stack([wx, wy], -1)
            if rule == "outline":
                m = _lookup(sdist, world_map, w, -99.0).min(1)
                np.minimum.at(margin, owner[a:a + chunk], m)
            else:
                off = (_lookup(road, world_map, w, 0) == 0).any(1)
                env_off[np.unique(owner[a:a + chunk][off])] = True
    return margin, env_off


def procedural_maps(name: str, seeds: range):
    cfg = world_config(name)
    for seed in seeds:
        yield seed, generate_city(cfg["map"], cfg["traffic"], np.random.default_rng(seed),
                                  cfg["clutter"])


def osm_maps():
    for path in OSM:
        if path.is_file():
            cfg = {"map": {"kind": "osm", "osm_file": str(path)}, "traffic": {"cars": 0}}
            yield path.name, World(cfg, seed=0).map


def summarise(rows: list[tuple]) -> dict:
    """Per kind: n, share leaving the road, worst overlap [m], 1st-percentile
    clearance [m], env15 share."""
    out = {}
    for kind in KINDS + ("all",):
        sel = [r for r in rows if kind in ("all", r[0])]
        if not sel:
            continue
        m = np.array([r[1] for r in sel])
        out[kind] = {"n": len(sel), "leaves_road": round(float(np.mean(m < 0)), 4),
                     "worst_overlap_m": round(float(max(-m.min(), 0.0)), 2),
                     "clearance_p1_m": round(float(np.percentile(m, 1)), 2),
                     "env15": round(float(np.mean([r[2] for r in sel])), 4)}
    return out


def measure_map(world_map: WorldMap) -> list[tuple[str, float, bool, int]]:
    """``(kind, margin [m], env15, lane)`` of each vehicle connector of a map."""
    lanes, names = connector_kinds(world_map)
    margin, env_off = swept_margin(world_map, signed_distance(world_map), lanes)
    return list(zip(names.tolist(), margin.tolist(), env_off.tolist(), lanes.tolist()))


def pursuit(name: str, n_turns: int, seed0: int = 0) -> dict:
    """Drive the autopilot ego (no traffic) through ``n_turns`` right-turn connectors
    (one per map, seeds from ``seed0``), from 20 m before the stop line at 6 m/s: its
    largest lateral offset from the lane centre on the connector [m] and the share
    flagged off-road there."""
    cfg = world_config(name)
    cfg = {**cfg, "traffic": {**cfg["traffic"], "cars": 0, "cyclists": 0, "pedestrians": 0,
                              "parked_density": 0.0}}
    cfg["traffic"]["stop_sign_prob"] = cfg["traffic"]["signal_prob"] = 0.0
    offsets, off = [], []
    seed = seed0
    while len(offsets) < n_turns:
        w = World(cfg, seed=seed)
        net = w.map.lanes
        lanes, names = connector_kinds(w.map)
        right = set(lanes[names == "right"].tolist())
        # road lanes (>= 21 m) that lead into a right turn
        cand = [int(p) for p in np.flatnonzero((net.kind == LaneKind.ROAD) & (net.length > 21.0))
                if right & set(net.successors(int(p)).tolist())]
        seed += 1
        if not cand:
            continue
        p = cand[int(np.random.default_rng(seed).integers(len(cand)))]
        w.place_ego(p, float(net.length[p] - 20.0), speed=6.0)
        if not w.set_turn(Turn.RIGHT):
            continue
        c = int(w.route[1])
        worst, flagged = 0.0, False
        for _ in range(300):
            w.step()
            if w.route[0] == c:
                worst = max(worst, -w.lane_offset)  # towards the kerb (right -)
                flagged = flagged or w.off_road
            elif worst > 0 or w.route[0] not in (p, c):
                break
        offsets.append(worst)
        off.append(flagged)
    return {"n": len(offsets), "max_lateral_offset_m": round(float(np.max(offsets)), 2),
            "mean_max_lateral_offset_m": round(float(np.mean(offsets)), 2),
            "off_road": round(float(np.mean(off)), 4)}


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=50, help="procedural seeds 0..N-1")
    ap.add_argument("--scenarios", default="default,dense,suburb",
                    help="comma-separated; 'occluded' is the occlusion task's world")
    ap.add_argument("--no-osm", action="store_true")
    ap.add_argument("--pursuit", type=int, default=0, help="driven right turns per scenario")
    ap.add_argument("--out", type=Path)
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    result: dict = {"command": "python docs/bends.py " + " ".join(argv or sys.argv[1:]),
                    "box_m": [LENGTH, WIDTH], "step_m": STEP}
    worst: list = []
    for name in args.scenarios.split(","):
        rows = []
        for seed, wm in procedural_maps(name, range(args.seeds)):
            got = measure_map(wm)
            rows += got
            worst += [(m, name, seed, k, ln) for k, m, _, ln in got]
        result[name] = summarise(rows)
        if args.pursuit:
            result[name]["pursuit_right"] = pursuit(name, args.pursuit)
        print(name, json.dumps(result[name]), file=sys.stderr, flush=True)
    if not args.no_osm:
        rows = []
        for label, wm in osm_maps():
            got = measure_map(wm)
            rows += got
            worst += [(m, "osm", label, k, ln) for k, m, _, ln in got]
        result["osm"] = summarise(rows)
    worst.sort(key=lambda r: r[0])
    result["worst"] = [{"scenario": n, "seed": s, "kind": k, "lane": ln, "margin_m": round(m, 2)}
                       for m, n, s, k, ln in worst[:12]]
    result["seconds"] = round(time.perf_counter() - t0, 1)
    text = json.dumps(result, indent=1)
    if args.out:
        args.out.write_text(text + "\n")
    print(text)
    return result


if __name__ == "__main__":
    main()
