"""Speed of the sensing chain at the paper's size (256 x 256 cells, 1800 beams, ~40 agents).

Runs on a self-contained synthetic street grid (:func:`synthetic_city`) so it does not
depend on the simulator; ``dstenv bench world`` measures the full chain on generated
cities. Reports the median time of each function and its ratio to a reference
numpy operation timed in the same process (a full-grid ``np.sin`` on 256 x 256
float64), so the figures can be compared across machines.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from typing import Any

import numpy as np

from dstenv.bench import median_ms
from dstenv.grid import GridSpec
from dstenv.sensing.gis import MapError, gis_grid
from dstenv.sensing.labels import label_grid, visible_mask
from dstenv.sensing.lidar import Lidar
from dstenv.sensing.raycast import sensor_grid
from dstenv.sim.types import AgentKind, Agents, MapClass, WorldMap

__all__ = ["run", "synthetic_city"]


def synthetic_city(
    seed: int = 0, n_agents: int = 40, blocks: int = 5, spacing: float = 60.0,
    road: float = 14.0, sidewalk: float = 3.0, resolution: float = 0.2,
) -> tuple[WorldMap, Agents, np.ndarray]:
    """A street grid with rectangular buildings, agents on the roads and an ego pose.

    Args:
        seed: random seed of building sizes and agent placement.
        n_agents: number of agents (80 % cars, the rest pedestrians on sidewalks).
        blocks: blocks per side.
        spacing: street centre-line spacing [m].
        road: road width [m]; sidewalk: sidewalk width [m]; resolution: raster cell [m].

    Returns:
        ``(world_map, agents, ego_pose)``; the ego stands on the central street.
    """
    rng = np.random.default_rng(seed)
    size = blocks * spacing
    n = int(round(size / resolution))
    centres = (np.arange(n) + 0.5) * resolution
    cx, cy = np.meshgrid(centres, centres)  # (row = y, column = x)
    raster = np.full((n, n), MapClass.INTERMEDIATE, dtype=np.uint8)
    street = np.arange(blocks + 1) * spacing
    for s in street:
        raster[np.abs(cy - s) <= road / 2] = MapClass.ROAD
        raster[np.abs(cx - s) <= road / 2] = MapClass.ROAD
    buildings = []
    inner = road / 2 + sidewalk
    for bx in range(blocks):
        for by in range(blocks):
            x_lo, y_lo = bx * spacing + inner, by * spacing + inner
            side = spacing - 2 * inner
            k = int(rng.integers(2, 4))
            cell = side / k
            for i in range(k):
                for j in range(k):
                    w, h = rng.uniform(0.55, 0.9, 2) * cell
                    x0, y0 = x_lo + i * cell, y_lo + j * cell
                    poly = np.array([[x0, y0], [x0 + w, y0], [x0 + w, y0 + h], [x0, y0 + h]])
                    buildings.append(poly)
                    inside = (cx >= x0) & (cx <= x0 + w) & (cy >= y0) & (cy <= y0 + h)
                    raster[inside] = MapClass.BUILDING
    world_map = WorldMap(raster, (0.0, 0.0), resolution, buildings)
    mid = street[blocks // 2]
    n_cars = int(round(0.8 * n_agents))
    along = rng.uniform(mid - 70, mid + 70, n_agents)
    lane = rng.choice([-5.0, -1.7, 1.7, 5.0], n_agents)
    lane[n_cars:] = rng.choice([-road / 2 - 1.5, road / 2 + 1.5], n_agents - n_cars)
    vertical = rng.random(n_agents) < 0.5
    xy = np.where(vertical[:, None], np.stack([mid + lane, along], 1),
                  np.stack([along, mid + lane], 1))
    yaw = np.where(vertical, np.pi / 2, 0.0) + np.where(lane > 0, np.pi, 0.0)
    kind = np.full(n_agents, AgentKind.CAR, np.uint8)
    kind[n_cars:] = AgentKind.PEDESTRIAN
    length = np.where(kind == AgentKind.CAR, 4.5, 0.5)
    width = np.where(kind == AgentKind.CAR, 1.8, 0.5)
    speed = rng.uniform(0.0, 12.0, n_agents) * (rng.random(n_agents) < 0.7)
    agents = Agents(xy, yaw, speed, length, width, kind, np.zeros(n_agents, bool))
    return world_map, agents, np.array([mid + 12.0, mid - 1.7, 0.0])


def run(args: argparse.Namespace) -> dict[str, Any]:
    """Time each sensing function; return ``{name: {"ms": ..., "x_ref": ...}}``."""
    repeats = args.repeats or (20 if args.quick else 300)
    spec = GridSpec()
    world_map, agents, pose = synthetic_city(0)
    rng = np.random.default_rng(0)
    lidar_poly = Lidar({"buildings": "polygons", "range_noise": 0.02, "dropout": 0.01})
    lidar_raster = Lidar({"buildings": "raster", "range_noise": 0.02, "dropout": 0.01})
    sweep = lidar_poly.sweep(world_map, agents, pose, rng)
    sensor = sweep.sensor_grid(spec)
    err = MapError.sample(world_map, {"offset_std": 0.3, "rotation_std": 0.01,
                                      "missing_building_prob": 0.1}, rng)
    ref = np.random.default_rng(1).random(spec.shape)
    pts_rng = np.random.default_rng(2)
    k_angles = pts_rng.uniform(-np.pi, np.pi, 60000)
    k_ranges = pts_rng.uniform(3.0, 60.0, 60000)
    k_hit = np.ones(60000, bool)
    cases: dict[str, Callable[[], Any]] = {
        "reference np.sin(256x256)": lambda: np.sin(ref),
        "sweep (polygons, 1800 beams, 40 agents)":
            lambda: lidar_poly.sweep(world_map, agents, pose, rng),
        "sweep (raster DDA)": lambda: lidar_raster.sweep(world_map, agents, pose, rng),
        "sensor_grid (1800 rays)": lambda: sweep.sensor_grid(spec),
        "gis_grid (exact)": lambda: gis_grid(world_map, pose, spec),
        "gis_grid (with MapError)": lambda: gis_grid(world_map, pose, spec, err),
        "label_grid (40 agents)": lambda: label_grid(world_map, agents, pose, spec),
        "visible_mask": lambda: visible_mask(sensor),
        "sensor_grid (60k KITTI-like rays)":
            lambda: sensor_grid(k_angles, k_ranges, k_hit, spec, 80.0),
    }
    results: dict[str, Any] = {}
    ref_ms = None
    for name, fn in cases.items():
        reps = max(repeats // 20, 3) if "60k" in name else repeats
        ms = median_ms(fn, reps)
        ref_ms = ref_ms or ms
        results[name] = {"ms": ms, "x_ref": ms / ref_ms}
        print(f"{name:42s} {ms:8.3f} ms  {ms / ref_ms:7.2f} x ref")
    chain = ["sweep (polygons, 1800 beams, 40 agents)", "sensor_grid (1800 rays)",
             "gis_grid (exact)", "label_grid (40 agents)", "visible_mask"]
    total = sum(results[k]["ms"] for k in chain)
    results["sensing chain total"] = {"ms": total, "x_ref": total / ref_ms}
    print(f"{'sensing chain total':42s} {total:8.3f} ms  {total / ref_ms:7.2f} x ref")
    return results


if __name__ == "__main__":
    run(argparse.Namespace(repeats=0, quick=False))
