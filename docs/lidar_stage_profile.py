"""Per-pass CPU profile of the 3-D LIDAR sweep and the point-cloud road, in one process.

Runs the stages of :meth:`dstenv.sensing.lidar3d.Hdl64.sweep` and of
:func:`dstenv.sensing.cloud.cloud_sensor_grid` one kernel at a time on the world of
``dstenv bench world`` (or, with ``--kitti``, the road on a real KITTI scan) and prints
the minimum CPU time of each over the rounds (a loaded machine: minima, not medians),
beside the whole calls. ``docs/realism-lidar.md`` (speed section) quotes it::

    cd /tmp && PYTHONPATH=/path/to/dstenv python /path/to/dstenv/docs/lidar_stage_profile.py 60
    cd /tmp && PYTHONPATH=/path/to/dstenv python /path/to/dstenv/docs/lidar_stage_profile.py 60 \\
        --kitti KITTI/training/velodyne/0003/000000.bin

The stage calls mirror the two functions; if they change, change this too (the sums
are printed beside the real calls to show a drift).
"""

import sys

if __name__ == "__main__" and {"-h", "--help"} & set(sys.argv[1:]):  # usage: the docstring
    print(__doc__)
    raise SystemExit(0)

import math
import sys
import time

import numpy as np

from dstenv.grid import GridSpec
from dstenv.sensing import cast3d, cloud, draws, ground, lidar3d, ransac, scene3d
from dstenv.sensing.polar import prepare_points
from dstenv.sim.bench import BENCH_CONFIG
from dstenv.sim.types import MapClass
from dstenv.sim.world import World

rounds = int(sys.argv[1]) if len(sys.argv) > 1 and sys.argv[1].isdigit() else 50
kitti = sys.argv[sys.argv.index("--kitti") + 1] if "--kitti" in sys.argv else None
world = World(BENCH_CONFIG, seed=0)
for _ in range(20):
    world.step()
spec = GridSpec()
hdl = lidar3d.Hdl64({"model": "hdl64"})
rng = np.random.default_rng(0)
c = hdl.config
gcfg, rcfg = c["ground"], c["rays"]
pose = np.asarray(world.ego_pose, dtype=np.float64)
wm = world.map
points = hdl.sweep(wm, world.agents, pose, rng, world.ego_speed).points
if kitti:
    points = np.fromfile(kitti, np.float32).reshape(-1, 4)
best_t: dict[str, float] = {}


def timed(name, fn, *args, **kwargs):
    t0 = time.process_time()
    out = fn(*args, **kwargs)
    best_t[name] = min(best_t.get(name, np.inf), time.process_time() - t0)
    return out


def sweep_stages():
    ox, oy, az, ux, uy = timed("sweep: column poses", lidar3d._column_poses, pose,
                               float(world.ego_speed), 0.0, hdl._tau, hdl.azimuth, hdl.mount)
    boxes = timed("sweep: box table", scene3d.box_table, world.agents, hdl._clutter,
                  c["vehicle_shape"] == "car")
    best, surf, idx = hdl._best, hdl._surf, hdl._idx
    timed("sweep: fill", best.fill, np.inf)
    cols = timed("sweep: column index", cast3d.column_index, ox, oy, az)
    common = (ox, oy, ux, uy, hdl.slope, hdl._neg_slope, float(c["mount_height"]),
              c["max_range"], best, surf, idx)
    timed("sweep: boxes", cast3d.cast_boxes, boxes, *cols, *common)
    timed("sweep: walls", cast3d.cast_walls, *hdl._walls, 2, *cols, *common)
    timed("sweep: ground and kerbs", cast3d.cast_ground, hdl._raster, hdl._dist,
          lidar3d.DIST_SHIFT, np.uint8(MapClass.INTERMEDIATE), float(wm.origin[0]),
          float(wm.origin[1]), float(wm.resolution), float(wm.kerb_height), ox, oy, ux, uy,
          hdl.slope, float(c["mount_height"]), c["max_range"], best, surf, idx)
    n = timed("sweep: count returns", lidar3d._count_returns, best)
    k_noise, k_drop, _ = draws.stream_keys(rng, 3)
    noise, inoise = timed("sweep: noise words", draws.beam_normal_words, k_noise, n)
    keep = timed("sweep: dropout", draws.beam_dropout, k_drop, n, float(c["dropout"]))
    outs = (np.empty((n, 4), np.float32), np.empty(n, np.int16), np.empty(n, np.int32),
            np.empty(n, np.uint8), np.empty(n, np.int32))
    timed("sweep: point pass", lidar3d._points, best, True, k_noise, float(c["range_noise"]),
          float(c["intensity_noise"]), noise, inoise, keep, surf, idx, hdl._cos_az,
          hdl._sin_az, hdl._cos_el, hdl._sin_el, hdl._sec_el, hdl._albedo,
          float(c["min_range"]), float(c["max_range"]), *outs)


def road_stages():
    xyz, polar = timed("road: prepare (copy, polar)", prepare_points, points)
    pick = timed("road: RANSAC candidates", ransac.candidates, xyz, polar[0],
                 float(gcfg["fit_range"]), float(gcfg["ego_radius"]),
                 float(gcfg["max_candidate_z"]))
    pick, tri = timed("road: RANSAC sample", ransac.sample_candidates, pick,
                      int(gcfg["sample"]), int(gcfg["iterations"]), gcfg["seed"])
    cand, _, plane = timed("road: RANSAC hypotheses", ransac.best_plane, xyz, pick, tri,
                           math.cos(math.radians(gcfg["max_tilt_deg"])),
                           float(gcfg["inlier_distance"]))
    plane = timed("road: refit", ransac.refit, cand, plane, float(gcfg["inlier_distance"]), 2)
    h, cell, flat = timed("road: local-ground walk", ground.ground_walk, xyz, plane, gcfg,
                          polar=polar)
    n_bins = max(round(360.0 / rcfg["azimuth_bin_deg"]), 1)
    _, gmask, omask, b, nearest = timed(
        "road: classification", cloud._classify_bins, polar[0], polar[1], h, cell, flat,
        float(gcfg["ego_radius"]), float(gcfg["ground_height"]),
        float(gcfg["min_obstacle_height"]), float(gcfg["max_obstacle_height"]),
        float(rcfg["block_height"]), n_bins)
    timed("road: rays (extents, own cells, rays)", cloud._rays, xyz, polar[0], b, nearest,
          gmask, omask, spec, rcfg["max_range"], rcfg["azimuth_bin_deg"],
          rcfg["occluded_hits"], rcfg["block_window_deg"])


whole = {"sweep (Hdl64.sweep)": lambda: hdl.sweep(wm, world.agents, pose, rng, world.ego_speed),
         "road (cloud_sensor_grid)": lambda: cloud.cloud_sensor_grid(points, spec, gcfg, rcfg)}
for _ in range(rounds + 1):  # the first round compiles / loads the caches
    if not kitti:
        sweep_stages()
    road_stages()
    for name, fn in whole.items():
        timed(name, fn)
for part in ("sweep", "road"):
    stages = {k: v for k, v in best_t.items() if k.startswith(part + ":")}
    for name, t in stages.items():
        print(f"{name:42s} {t * 1e3:6.3f} ms")
    if stages:
        print(f"{part + ': sum of the stages':42s} {sum(stages.values()) * 1e3:6.3f} ms")
for name in whole:
    if not (kitti and name.startswith("sweep")):
        print(f"{name:42s} {best_t[name] * 1e3:6.3f} ms")
print(f"[CPU time, minimum of {rounds} rounds; {len(points)} points]")
