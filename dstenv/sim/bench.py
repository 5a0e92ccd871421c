"""``dstenv bench world``: one simulation step of the whole chain at 256 x 256 cells.

world step (traffic + ego autopilot) + LIDAR sweep (1800 beams) + sensor grid +
GIS grid + label grid + visible mask, in a generated city with about 40 agents and
its street clutter (the default, realistic world). The same chain in the ``clean``
world (no clutter, ideal parking) is timed in the same process, and the ratio of the
two is the cost of realism on this machine.
Each part is timed alone and the chain as a whole; every figure is also given as
a ratio to a reference computation (``np.sin`` over 256 x 256 floats) run in the
same process, so the numbers compare across machines. Goal: chain <= 2 ms.
Beside it the 3-D LIDAR (``lidar.model = "hdl64"``, 64 x 2048 beams): its sweep and
the point-cloud road to the grid (ground removal, then rays; each also alone);
goal <= 10 ms together.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from typing import Any

import numpy as np

from dstenv.bench import median_min_ms
from dstenv.grid import GridSpec
from dstenv.sim.world import World

__all__ = ["run", "BENCH_CONFIG"]

#: a 3 x 3 block city with about 40 agents (moving, parked, pedestrians)
BENCH_CONFIG = {
    "map": {"blocks_x": 3, "blocks_y": 3},
    "traffic": {"cars": 14, "cyclists": 2, "pedestrians": 12, "parked_density": 0.08},
}


def run(args: argparse.Namespace) -> dict[str, Any]:
    """Time the world step and the sensing chain; return ``{name: {"ms", "x_ref"}}``."""
    quick = bool(getattr(args, "quick", False))
    repeats = int(getattr(args, "repeats", 0) or 0) or (30 if quick else 300)
    world = World(BENCH_CONFIG, seed=0)
    for _ in range(20):  # let traffic settle
        world.step()
    spec = GridSpec()
    ref = np.random.default_rng(1).random(spec.shape)
    rng = np.random.default_rng(0)
    cases: dict[str, Callable[[], Any]] = {"reference np.sin(256x256)": lambda: np.sin(ref),
                                           "world step": world.step}
    try:
        from dstenv.sensing import Lidar, gis_grid, label_grid, visible_mask
    except ImportError:  # sensing not part of this build: the world step alone
        Lidar = None
    if Lidar is not None:
        lidar = Lidar()

        def sweep():
            return lidar.sweep(world.map, world.agents, world.ego_pose, rng)

        def chain_of(w: World) -> Callable[[], None]:
            def chain() -> None:
                w.step()
                agents, pose = w.agents, w.ego_pose
                s = lidar.sweep(w.map, agents, pose, rng)
                sensor = s.sensor_grid(spec)
                gis_grid(w.map, pose, spec)
                label_grid(w.map, agents, pose, spec)
                visible_mask(sensor)
            return chain

        chain = chain_of(world)

        from dstenv.config import merge_config
        from dstenv.scenario_files import load_scenario
        from dstenv.sim.config import default_config

        clean_cfg = merge_config(default_config(), load_scenario("clean")["world"], "clean")
        clean = World(merge_config(clean_cfg, BENCH_CONFIG, "bench"), seed=0)
        for _ in range(20):
            clean.step()

        clean_chain = chain_of(clean)

        last = sweep()
        cases.update({
            "LIDAR sweep (1800 beams)": sweep,
            "sensor grid": lambda: last.sensor_grid(spec),
            "GIS grid": lambda: gis_grid(world.map, world.ego_pose, spec),
            "label grid": lambda: label_grid(world.map, world.agents, world.ego_pose, spec),
            "step + sweep + grids + labels": chain,
            "the same, clean world": clean_chain,
        })
        from dstenv.sensing.lidar3d import Hdl64

        hdl = Hdl64({"model": "hdl64"})  # 64 x 2048 beams

        def sweep3d():
            return hdl.sweep(world.map, world.agents, world.ego_pose, rng, world.ego_speed)

        from dstenv.sensing.cloud import scan_sensor_grid
        from dstenv.sensing.ground import (
            classify_points,
            fit_ground_plane,
            ground_config,
        )
        from dstenv.sensing.polar import prepare_points

        cloud = sweep3d()
        # the stages of the point-cloud road on this cloud, as cloud_sensor_grid runs them
        # (its float32 copy of the points and their polar coordinates first)
        gcfg = ground_config(hdl.config["ground"])
        offset = (float(cloud.mount[0]), float(cloud.mount[1]))
        xyz, polar = prepare_points(cloud.points, offset)
        plane = fit_ground_plane(xyz, gcfg, polar=polar)
        ground, obstacle, height = classify_points(xyz, plane, gcfg, polar=polar)
        rays = hdl.config["rays"]

        def removal():
            pts, pol = prepare_points(cloud.points, offset)
            classify_points(pts, fit_ground_plane(pts, gcfg, polar=pol), gcfg, polar=pol)

        cases.update({
            "hdl64 sweep (64 x 2048 beams)": sweep3d,
            "  ground removal (plane, local)": removal,
            "  rays into the grid": lambda: scan_sensor_grid(
                xyz, ground, obstacle, spec, rays["max_range"], rays["azimuth_bin_deg"],
                rays["occluded_hits"], blocking=obstacle & (height >= rays["block_height"]),
                block_window_deg=rays["block_window_deg"], polar=polar),
            "hdl64 ground removal + sensor grid": lambda: cloud.sensor_grid(spec),
            "hdl64 sweep + sensor grid (goal 10)": lambda: sweep3d().sensor_grid(spec),
        })
    print(f"world: {len(world.agents)} agents ({int((~world.agents.parked).sum())} mobile), "
          f"{len(world.map.obstacles)} clutter boxes, "
          f"{len(world.map.lanes)} lanes, map {world.map.raster.shape[1]}x"
          f"{world.map.raster.shape[0]} cells; grid {spec.height}x{spec.width}")
    results: dict[str, Any] = {"agents": len(world.agents)}
    ref_ms = None
    print(f"{'':34s} {'median':>11s}  {'x ref':>7s}  {'min':>9s}")
    for name, fn in cases.items():
        ms, best = median_min_ms(fn, repeats, warmup=3)
        ref_ms = ref_ms or ms
        results[name] = {"ms": ms, "x_ref": ms / ref_ms, "min_ms": best}
        print(f"{name:34s} {ms:8.3f} ms  {ms / ref_ms:7.2f}  {best:6.3f} ms")
    if Lidar is None:
        print("dstenv.sensing not available: world step only")
    else:
        ratio = results["step + sweep + grids + labels"]["ms"] / \
            results["the same, clean world"]["ms"]
        results["realistic / clean"] = ratio
        print(f"{'realistic / clean chain':34s} {ratio:8.2f}")
    return results


if __name__ == "__main__":
    run(argparse.Namespace(repeats=0, quick=False))
