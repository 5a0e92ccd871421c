"""Sensor and label grids: hand-placed points and boxes, then the real sample."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.ndimage import binary_dilation

from dstenv.dst import CLASSES, SensorState
from dstenv.frame import IGNORE_INDEX
from dstenv.grid import GridSpec
from dstenv.kitti.grids import box_mask, camera_fov, dontcare_cells, label_grid
from dstenv.kitti.objects import Boxes
from dstenv.kitti.readers import read_calib
from dstenv.kitti.sequence import KittiSequence, convert_sequence
from dstenv.sensing.cloud import scan_sensor_grid
from dstenv.sim.types import MapClass

from .conftest import FIXTURES

SPEC = GridSpec(64, 64, 0.5)  # ego cell (32, 32); x = (32 - i) * 0.5, y = (32 - j) * 0.5
NAV, STATIC, MOVING = (CLASSES.index(c) for c in ("navigable", "static", "moving"))


def _boxes(centres, yaw=0.0, length=4.0, width=2.0):
    n = len(centres)
    c = np.column_stack([np.asarray(centres, float), np.zeros(n)])
    return Boxes(frame=np.zeros(n, np.int64), track=np.arange(n), type=np.zeros(n, np.int64),
                 centre=c, length=np.full(n, length), width=np.full(n, width),
                 height=np.full(n, 1.5), yaw=np.full(n, yaw))


def test_sensor_grid_first_hit_and_occluded_hits():
    pts = np.array([[5.0, 0.0, 0.0],  # obstacle 5 m ahead: cell (22, 32)
                    [8.0, 0.0, 0.0],  # obstacle behind it: cell (16, 32), occupied, not cleared
                    [10.0, 0.0, -1.7],  # ground seen over the first obstacle: clipped
                    [0.0, 6.0, -1.7]])  # ground 6 m left: cells (32, 32..20) free
    ground = np.array([False, False, True, True])
    obstacle = ~ground
    g = scan_sensor_grid(pts, ground, obstacle, SPEC, 60.0)
    assert g[22, 32] == SensorState.OCCUPIED and g[16, 32] == SensorState.OCCUPIED
    assert (g[23:32, 32] == SensorState.FREE).all()
    assert (g[17:22, 32] == SensorState.UNKNOWN).all() and g[12, 32] == SensorState.UNKNOWN
    assert (g[32, 20:32] == SensorState.FREE).all() and g[32, 19] == SensorState.UNKNOWN
    g2 = scan_sensor_grid(pts, ground, obstacle, SPEC, 60.0, occluded_hits=False)
    assert g2[16, 32] == SensorState.UNKNOWN
    # a low obstacle that does not block: the ground beyond is seen over it
    g3 = scan_sensor_grid(pts, ground, obstacle, SPEC, 60.0, blocking=np.zeros(4, bool))
    assert (g3[13:32, 32] != SensorState.UNKNOWN).all() and g3[22, 32] == SensorState.OCCUPIED


def test_box_mask_cells():
    m = box_mask(_boxes([[5.0, 0.0]]), SPEC)[0]  # 4 x 2 m centred 5 m ahead
    rows, cols = np.nonzero(m)
    assert rows.min() == 32 - 14 and rows.max() == 32 - 6  # x in [3, 7]
    assert cols.min() == 32 - 2 and cols.max() == 32 + 2  # y in [-1, 1]
    m90 = box_mask(_boxes([[5.0, 0.0]], yaw=np.pi / 2), SPEC)[0]
    assert np.ptp(np.nonzero(m90)[0]) == 4 and np.ptp(np.nonzero(m90)[1]) == 8
    tiny = box_mask(_boxes([[5.1, 0.1]], length=0.1, width=0.1), SPEC)[0]
    assert tiny.sum() == 1 and tiny[22, 32]  # the centre cell is always labelled


def test_camera_fov_of_fixture_calibration():
    fov = camera_fov(read_calib(FIXTURES / "calib_colons.txt"), SPEC, image_width=1242)
    x, y = SPEC.cell_centers()
    assert fov[x > 1].any() and not fov[x < 0].any()  # nothing behind the camera
    # fx = 700, cx = 600 (+45 px offset): left edge at ~40.7 deg, right edge at ~42.5 deg
    ang = np.degrees(np.arctan2(y, x))
    assert fov[(x > 5) & (np.abs(ang) < 38)].all()
    assert not fov[(x > 5) & (np.abs(ang) > 45)].any()


def test_label_grid_precedence():
    sensor = np.full(SPEC.shape, SensorState.FREE, np.uint8)
    sensor[:, :10] = SensorState.UNKNOWN
    fov = np.zeros(SPEC.shape, bool)
    fov[:32] = True  # the front half
    dontcare = np.zeros(SPEC.shape, bool)
    dontcare[0:4, 30:34] = True
    boxes = _boxes([[5.0, 0.0], [5.0, 5.0], [-10.0, 0.0]])
    lab = label_grid(boxes, np.array([True, False, False]), sensor, fov, dontcare, SPEC)
    assert lab[22, 32] == MOVING and lab[22, 22] == STATIC
    assert lab[52, 32] == STATIC  # a box behind the camera is still labelled
    assert lab[10, 40] == NAV  # seen free, in view
    assert lab[10, 5] == IGNORE_INDEX  # unseen
    assert lab[45, 40] == IGNORE_INDEX  # behind: not annotated by KITTI
    assert (lab[0:4, 30:34] == IGNORE_INDEX).all()  # DontCare
    ign = label_grid(boxes, np.zeros(3, bool), sensor, fov, dontcare, SPEC, free_label="ignore")
    assert ign[10, 40] == IGNORE_INDEX and ign[22, 32] == STATIC
    gis = np.full(SPEC.shape, MapClass.BUILDING, np.uint8)
    gis[:, 40:] = MapClass.ROAD
    withmap = label_grid(boxes, np.zeros(3, bool), sensor, fov, dontcare, SPEC, gis=gis)
    assert withmap[10, 5] == CLASSES.index("building") and withmap[10, 50] == NAV
    with pytest.raises(ValueError, match="free_label must be one of navigable, ignore"):
        label_grid(boxes, np.zeros(3, bool), sensor, fov, dontcare, SPEC, free_label="road")


def test_dontcare_cells_from_projected_points():
    calib = read_calib(FIXTURES / "calib_colons.txt")
    pts = np.array([[10.0, -3.0, -1.0], [10.0, 3.0, -1.0], [-10.0, 3.0, -1.0]])
    # (10, -3): camera (3, 0.92, 9.73) -> u = (700 * 3 + 600 * 9.73 + 45) / 9.73 ~ 820.5
    u = (700 * 3 + 600 * 9.73 + 45) / 9.73
    box = np.array([[u - 5, 0, u + 5, 400]])
    cells = dontcare_cells(pts, np.ones(3, bool), box, calib, SPEC, dilation=0)
    i, j = SPEC.to_cell(10.0, -3.0)
    assert cells.sum() == 1 and cells[i, j]
    assert dontcare_cells(pts, np.ones(3, bool), box, calib, SPEC, dilation=1).sum() == 5


def test_synthetic_labels_and_occupancy(tiny_root):
    seq = KittiSequence(tiny_root, "0001")
    spec = GridSpec()
    for frame in convert_sequence(seq, {"stride": 1, "warmup": 0}):
        boxes = seq.boxes.select(seq.boxes.frame == frame.step)
        masks = box_mask(boxes, spec)
        for k in range(len(boxes)):
            want = MOVING if boxes.track[k] == 0 else STATIC
            assert (frame.labels[masks[k]] == want).all()
            # the box surface lies on the footprint's edge: count a 1-cell margin
            occ = frame.sensor == SensorState.OCCUPIED
            assert occ[binary_dilation(masks[k])].sum() >= 20
            assert binary_dilation(occ)[masks[k]].mean() >= 0.45
            assert (frame.sensor[masks[k]] == SensorState.FREE).mean() < 0.1
        # the pole's DontCare region is ignored; the pole is occupied in the sensor grid
        i, j = spec.to_cell(25.0 - frame.step, -10.0)
        assert frame.sensor[i, j] == SensorState.OCCUPIED and frame.labels[i, j] == IGNORE_INDEX
        assert set(np.unique(frame.labels)) <= {NAV, STATIC, MOVING, IGNORE_INDEX}


def test_real_cars_on_occupied_cells(real_root):
    """Labelled cars cover occupied cells; the same boxes moved onto the road do not."""
    seq = KittiSequence(real_root, "0003")
    spec = GridSpec()
    near, free, shifted = [], [], []
    for frame in convert_sequence(seq, {"stride": 4, "warmup": 0, "update_every": 4}):
        occ = frame.sensor == SensorState.OCCUPIED
        near_occ = binary_dilation(occ)
        boxes = seq.boxes.select(seq.boxes.frame == frame.step)
        masks = box_mask(boxes, spec)
        moved = boxes.select(np.ones(len(boxes), bool))
        moved.centre = moved.centre + [0.0, 3.0, 0.0]  # into the ego lane / verge
        moved_masks = box_mask(moved, spec)
        for k in range(len(boxes)):
            if masks[k].sum() < 20:  # outside the grid
                continue
            assert occ[masks[k]].sum() >= 5
            near.append(near_occ[masks[k]].mean())
            free.append((frame.sensor[masks[k]] == SensorState.FREE).mean())
            shifted.append(near_occ[moved_masks[k]].mean())
    assert len(near) >= 12
    assert np.mean(near) > 0.6 and np.min(near) > 0.3
    assert np.mean(free) < 0.15  # rays stop at the car: its footprint is not "seen free"
    assert np.mean(shifted) < 0.5 * np.mean(near)


def test_kitti_convention_relabels_a_simulated_frame():
    from dstenv.kitti.grids import kitti_convention

    labels = np.array([[0, 1, 2, 3, 4, 255]], np.uint8)
    free = np.full(labels.shape, 1, np.uint8)
    np.testing.assert_array_equal(kitti_convention(labels, free), [[0, 0, 0, 3, 4, 0]])
    occupied = np.full(labels.shape, 2, np.uint8)
    np.testing.assert_array_equal(kitti_convention(labels, occupied),
                                  [[255, 255, 255, 3, 4, 255]])
    unseen = np.zeros(labels.shape, np.uint8)
    np.testing.assert_array_equal(kitti_convention(labels, unseen),
                                  [[255, 255, 255, 3, 4, 255]])
    with pytest.raises(ValueError, match="differ"):
        kitti_convention(labels, unseen[:, :3])
