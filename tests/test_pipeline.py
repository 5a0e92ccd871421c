"""The gym-free pipeline: world -> sweep -> grids -> DST filter -> Frame."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from dstenv.config import ConfigError
from dstenv.dst import CLASSES
from dstenv.pipeline import Pipeline, default_config
from dstenv.sensing.labels import label_grid


GRID = {"height": 48, "width": 40, "cell_size": 1.0}
HIGHWAY = {"source": "highway", "grid": GRID, "lidar": {"beams": 360},
           "highway": {"resolution": 0.5}, "frame": {"masses": True, "lidar_points": True}}
CITY = {"grid": GRID, "lidar": {"beams": 360}, "frame": {"masses": True, "lidar_points": True}}
SOURCES = [pytest.param(HIGHWAY, id="highway"), pytest.param(CITY, id="city")]


@pytest.mark.parametrize("cfg", SOURCES)
def test_frames_have_documented_shapes_and_valid_contents(cfg):
    p = Pipeline(cfg)
    first = p.reset(seed=4)
    assert first.step == 0 and first.time == 0.0 and first.seed == 4
    assert np.array_equal(first.pignistic_prev, first.pignistic)
    prev = first
    for k in range(1, 6):
        f = p.step()
        assert f.step == k and f.time == pytest.approx(0.1 * k)
        assert f.pignistic.shape == (5, 48, 40) and f.pignistic.dtype == np.float32
        assert np.array_equal(f.pignistic_prev, prev.pignistic)
        assert f.masses.shape == (32, 48, 40) and f.masses.dtype == np.float32
        assert f.masses.min() >= 0 and np.allclose(f.masses.sum(axis=0), 1.0, atol=1e-5)
        assert np.allclose(f.pignistic.sum(axis=0), 1.0, atol=1e-5)
        assert f.labels.dtype == np.uint8 and f.labels.max() < len(CLASSES)
        assert f.visible.dtype == bool and np.array_equal(f.visible, f.sensor != 0)
        assert f.sensor.dtype == np.uint8 and f.sensor.max() <= 2
        assert f.gis.dtype == np.uint8 and f.gis.max() <= 3
        assert f.ego_pose.shape == (3,) and f.ego_pose.dtype == np.float64
        assert f.extras["lidar_points"].shape == (360, 2)
        # labels are exactly the sensing module's ground truth at the frame's pose
        w = p.world
        assert np.array_equal(f.labels, label_grid(w.map, w.agents, f.ego_pose, p.spec))
        prev = f
    # the ego cell is seen free or occupied: the sensor sits there
    assert f.visible[p.spec.ego_cell]


@pytest.mark.parametrize("cfg", SOURCES)
def test_same_seed_same_frames(cfg):
    a, b = Pipeline(cfg), Pipeline(cfg)
    fa, fb = a.reset(7), b.reset(7)
    for _ in range(10):
        fa, fb = a.step(), b.step()
    assert np.array_equal(fa.masses, fb.masses) and np.array_equal(fa.labels, fb.labels)
    assert np.array_equal(fa.ego_pose, fb.ego_pose)


def test_reset_keep_map_drives_the_same_map_with_the_new_seeds_traffic():
    p = Pipeline(CITY)
    with pytest.raises(RuntimeError, match="reset once without it first"):
        p.reset(5, keep_map=True)
    p.reset(5)
    city = p.world.map
    kept = p.reset(9, keep_map=True)
    assert p.world.map is city and p.seed == 9
    fresh = Pipeline(CITY).reset(9)  # seed 9's own map: another city, another start
    assert not np.array_equal(kept.ego_pose, fresh.ego_pose)
    again = Pipeline(CITY)
    again.reset(5)
    same = again.reset(9, keep_map=True)  # the same two calls give the same episode
    assert np.array_equal(kept.sensor, same.sensor) and np.array_equal(kept.gis, same.gis)


def test_reset_keep_map_refuses_a_world_without_a_map_to_keep():
    pytest.importorskip("highway_env")
    p = Pipeline(HIGHWAY)
    p.reset(3)
    with pytest.raises(ValueError, match="a HighwayWorld cannot keep its map"):
        p.reset(4, keep_map=True)
    assert p.seed == 3  # refused before anything changed


def test_observed_building_gets_building_belief():
    # after a few sweeps, cells the map calls building and the LIDAR saw occupied
    # carry most of their belief on "building"
    p = Pipeline(HIGHWAY)
    p.reset(seed=1)
    for _ in range(5):
        f = p.step()
    seen_building = (f.gis == 1) & (f.sensor == 2)
    if seen_building.any():
        assert f.pignistic[CLASSES.index("building")][seen_building].mean() > 0.5
    road_free = (f.gis == 2) & (f.sensor == 1)
    assert road_free.any()
    assert f.pignistic[CLASSES.index("navigable")][road_free].mean() > 0.5


def test_errors_are_named():
    msg = "source: unknown world source 'carla'; allowed: city, highway"
    with pytest.raises(ConfigError, match=msg):
        Pipeline({"source": "carla"})
    with pytest.raises(ConfigError, match="config.dst.beta: unknown key"):
        Pipeline({"dst": {"beta": 1.0}})
    with pytest.raises(RuntimeError, match="call reset"):
        Pipeline(HIGHWAY).step()


def test_default_config_sections():
    cfg = default_config()
    assert {"world", "lidar", "grid", "gis", "labels", "dst"} <= set(cfg)
    assert cfg["grid"] == {"height": 256, "width": 256, "cell_size": 0.33}


def test_core_modules_do_not_import_gymnasium():
    root = Path(__file__).resolve().parents[1] / "dstenv"
    for rel in ("pipeline.py", "sim/highway.py"):
        src = (root / rel).read_text()
        assert not re.search(r"^\s*(import|from)\s+gymnasium", src, re.M), rel


def test_protocol_fuses_every_kth_step_with_the_previous_fused_frame():
    p = Pipeline({**CITY, "protocol": {"update_every": 3}})
    frames = [p.reset(seed=2)] + [p.step() for _ in range(6)]
    for k in (1, 2):  # between fused steps: the last fused BetP, fresh sensor grid
        assert np.array_equal(frames[k].pignistic, frames[0].pignistic)
    assert np.array_equal(frames[3].pignistic_prev, frames[0].pignistic)
    assert np.array_equal(frames[6].pignistic_prev, frames[3].pignistic)
    assert not np.array_equal(frames[3].pignistic, frames[0].pignistic)
    # the fused frames equal a pipeline fed only those sensor / GIS grids and poses
    from dstenv.dst.tracker import GridTracker

    tr = GridTracker((48, 40), cell_size=1.0)
    for k in (0, 3, 6):
        out = tr.step(frames[k].sensor, frames[k].gis, frames[k].ego_pose)
    np.testing.assert_array_equal(out.betp, frames[6].pignistic)


def test_protocol_camera_fov_and_kitti_moving_rule():
    p = Pipeline({**CITY, "protocol": {"camera_fov": 81.0, "moving_rule": "displacement",
                                       "update_every": 10}})
    f = p.reset(seed=5)
    x, y = p.spec.cell_centers()
    inside = (x > 0) & (np.abs(np.arctan2(y, x)) <= np.deg2rad(40.5))
    assert np.all(f.labels[~inside] == 255) and np.all(f.labels[inside] != 255)
    assert p.moving_threshold == pytest.approx(0.1)  # 10 cm per 1 s between fused frames
    assert Pipeline({**CITY, "protocol": {"moving_rule": "displacement"}}).moving_threshold == \
        pytest.approx(1.0)
    with pytest.raises(ConfigError, match="protocol.moving_rule"):
        Pipeline({**CITY, "protocol": {"moving_rule": "smoothed"}})
    with pytest.raises(ConfigError, match="protocol.update_every"):
        Pipeline({**CITY, "protocol": {"update_every": 0}})


def test_hdl64_pipeline_is_deterministic_and_sees_through_kittis_road():
    cfg = {"grid": {"height": 96, "width": 96, "cell_size": 0.33},
           "lidar": {"model": "hdl64", "hdl64": {"azimuth_step": 0.7}},
           "frame": {"lidar_points": True}}
    a, b = Pipeline(cfg), Pipeline(cfg)
    fa, fb = a.reset(seed=3), b.reset(seed=3)
    fa, fb = a.step(), b.step()
    assert np.array_equal(fa.sensor, fb.sensor) and np.array_equal(fa.pignistic, fb.pignistic)
    assert fa.extras["lidar_points"].shape == (64 * 514, 4)
    shares = np.bincount(fa.sensor.ravel(), minlength=3) / fa.sensor.size
    assert shares[1] > 0.2 and shares[2] > 0.0


def test_degenerate_sensor_settings():
    # a 3-D scan without ground (every beam dropped) is no evidence, not a crash mid-episode
    p = Pipeline({"grid": {"height": 32, "width": 32},
                  "lidar": {"model": "hdl64", "hdl64": {"dropout": 1.0, "azimuth_step": 2.0}}})
    frame = p.reset(seed=0)
    assert not frame.sensor.any()  # SensorState.UNKNOWN everywhere
    # a LIDAR mounted off the grid is refused when the pipeline is built (it was refused
    # by the ray caster at the first reset)
    with pytest.raises(ConfigError, match="lidar.mount_x / mount_y 10, -10 m: outside the grid"):
        Pipeline({"grid": {"height": 32, "width": 32}, "lidar": {"mount_x": 10, "mount_y": -10}})
    with pytest.raises(ValueError, match="seed must be an integer >= 0, got -1"):
        p.reset(seed=-1)
    for seed in (1.5, None, "3", True):  # 1.5 was taken as 1, None was a TypeError
        with pytest.raises(ValueError, match=f"seed must be an integer >= 0, got {seed!r}"):
            p.reset(seed=seed)
    assert p.reset(seed=np.int64(2)).seed == 2


def test_protocol_object_edges_ignores_the_occupied_rim_of_road_users():
    from dstenv.sensing.labels import ignore_object_edges

    base = Pipeline(CITY)
    rim = Pipeline({**CITY, "protocol": {"object_edges": "ignore"}})
    changed = 0
    for seed in (5, 6):
        a, b = base.reset(seed=seed), rim.reset(seed=seed)
        for _ in range(8):
            a, b = base.step(), rim.step()
            np.testing.assert_array_equal(a.pignistic, b.pignistic)  # labels only
            want = a.labels.copy()
            changed += ignore_object_edges(want, a.sensor, 255)
            np.testing.assert_array_equal(b.labels, want)
    assert changed > 0  # the rule met some rims in these drives
    with pytest.raises(ConfigError, match="protocol.object_edges"):
        Pipeline({**CITY, "protocol": {"object_edges": "dilate"}})


def test_frames_share_betp_read_only_so_no_frame_changes_another():
    """Attack 16: f0.pignistic[:] = 0 wiped f1's t-1 input (the same buffer, writable)."""
    p = Pipeline({"grid": {"height": 32, "width": 32}})
    f0 = p.reset(3)
    f1 = p.step()
    assert np.shares_memory(f1.pignistic_prev, f0.pignistic)  # shared, as documented
    for frame in (f0, f1):
        for a in (frame.pignistic, frame.pignistic_prev):
            with pytest.raises(ValueError, match="read-only"):
                a[:] = 0
    x = f1.fcn_input()
    x[:] = 0  # the stacked input is the caller's own array
    assert f0.pignistic.sum() > 0
    p = Pipeline({"grid": {"height": 32, "width": 32}, "protocol": {"update_every": 2}})
    p.reset(3)
    g1 = p.step()  # not fused: carries the last fused BetP (computed here, once)
    with pytest.raises(ValueError, match="read-only"):
        g1.pignistic[0, 0, 0] = 1.0


def test_reset_refuses_a_seed_past_int64_and_a_keep_map_that_is_no_bool():
    """Attack 16: seed 2**70 failed only in the shard writer's close; keep_map="no" was
    taken as true."""
    p = Pipeline({"grid": {"height": 16, "width": 16}})
    with pytest.raises(ValueError, match=r"seed must be an integer >= 0, got \d+ \(at most"):
        p.reset(2**70)
    p.reset(2**63 - 1)
    with pytest.raises(ValueError, match="keep_map must be True or False, got 'no'"):
        p.reset(2, keep_map="no")


def test_a_meta_action_name_in_the_city_world_is_named():
    """Attack 16: step("left") said only 'could not convert string to float'."""
    p = Pipeline({"grid": {"height": 16, "width": 16}})
    p.reset(1)
    for bad in ("left", (np.nan, 0.0), (1.0, 2.0, 3.0)):
        with pytest.raises(ValueError, match=r"ego_action must be finite \(accel, steer\), got"):
            p.step(bad)
    p.step((0.5, 0.0))
