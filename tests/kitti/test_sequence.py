"""Sequence conversion: strides, skipped frames, config validation, real-sample frames."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from dstenv.config import ConfigError
from dstenv.dst import CLASSES, SensorState
from dstenv.frame import IGNORE_INDEX
from dstenv.kitti.readers import KittiError
from dstenv.kitti.sequence import KittiSequence, convert_sequence, kitti_config


def test_stride_poses_and_inputs(tiny_root):
    seq = KittiSequence(tiny_root, "1")  # padded to 0001
    frames = list(convert_sequence(seq, {"stride": 2, "warmup": 0}))
    assert [f.step for f in frames] == [0, 2, 4]
    np.testing.assert_allclose([f.ego_pose for f in frames], [[0, 0, 0], [2, 0, 0], [4, 0, 0]],
                               atol=1e-6)
    assert [f.time for f in frames] == [0.0, 0.2, 0.4]
    assert all(f.seed == 1 for f in frames)
    f0, f1 = frames[0], frames[1]
    np.testing.assert_array_equal(f0.pignistic_prev, f0.pignistic)
    # the filter ran on every scan: t-1 is frame 1, not the previous kept frame
    every = list(convert_sequence(seq, {"stride": 1, "warmup": 0}))
    np.testing.assert_array_equal(f1.pignistic_prev, every[1].pignistic)
    np.testing.assert_array_equal(f1.pignistic, every[2].pignistic)
    sparse = list(convert_sequence(seq, {"stride": 2, "warmup": 0, "update_every": 2}))
    np.testing.assert_array_equal(sparse[1].pignistic_prev, sparse[0].pignistic)
    assert not np.array_equal(sparse[1].pignistic, f1.pignistic)
    np.testing.assert_allclose(f1.pignistic.sum(axis=0), 1.0, atol=1e-5)
    np.testing.assert_array_equal(f1.visible, f1.sensor != SensorState.UNKNOWN)
    assert (f1.gis == 0).all()  # no map: vacuous


def test_deterministic(tiny_root):
    seq = KittiSequence(tiny_root, "0001")
    a = list(convert_sequence(seq, {"stride": 3, "warmup": 1}))
    b = list(convert_sequence(seq, {"stride": 3, "warmup": 1}))
    assert [f.step for f in a] == [1, 4]
    for fa, fb in zip(a, b, strict=True):
        np.testing.assert_array_equal(fa.pignistic, fb.pignistic)
        np.testing.assert_array_equal(fa.labels, fb.labels)


def test_missing_and_truncated_scans_are_skipped_and_logged(tiny_root, caplog):
    vel = tiny_root / "training" / "velodyne" / "0001"
    (vel / "000002.bin").unlink()
    data = (vel / "000004.bin").read_bytes()
    (vel / "000004.bin").write_bytes(data[:-10])
    seq = KittiSequence(tiny_root, "0001")
    skipped: list[str] = []
    with caplog.at_level(logging.WARNING, logger="dstenv.kitti"):
        frames = list(convert_sequence(seq, {"stride": 1, "warmup": 0}, skipped=skipped))
    assert [f.step for f in frames] == [0, 1, 3, 5]
    assert len(skipped) == 2
    assert "frame 2: skipped" in skipped[0] and "missing Velodyne scan" in skipped[0]
    assert "000004.bin" in skipped[1] and "not a positive multiple of 16" in skipped[1]
    assert sum("skipped" in r.message for r in caplog.records) == 2
    # the filter moved from frame 1 straight to frame 3: the pose is still right
    np.testing.assert_allclose(frames[2].ego_pose, [3, 0, 0], atol=1e-6)


def test_sequence_file_errors(tiny_root):
    split = tiny_root / "training"
    with pytest.raises(KittiError, match="missing scan folder"):
        KittiSequence(tiny_root, "0002")
    with pytest.raises(KittiError, match="not a number"):
        KittiSequence(tiny_root, "abc")
    lines = (split / "oxts" / "0001.txt").read_text().splitlines()
    (split / "oxts" / "0001.txt").write_text("\n".join(lines[:3]) + "\n")
    msg = r"0001\.txt: labels for frame 5 but the OXTS file has only 3"
    with pytest.raises(KittiError, match=msg):
        KittiSequence(tiny_root, "0001")
    (split / "calib" / "0001.txt").unlink()
    with pytest.raises(KittiError, match=r"calib/0001\.txt: missing calibration file"):
        KittiSequence(tiny_root, "0001")


def test_config_validation():
    with pytest.raises(ConfigError, match="unknown key 'strid'"):
        kitti_config({"strid": 2})
    with pytest.raises(ConfigError, match="kitti.labels.rule: 'fast'"):
        kitti_config({"labels": {"rule": "fast"}})
    with pytest.raises(ConfigError, match="kitti.stride: must be >= 1"):
        kitti_config({"stride": 0})
    with pytest.raises(ConfigError, match="multiples of kitti.update_every"):
        kitti_config({"update_every": 2, "stride": 5})
    with pytest.raises(ConfigError, match="alpha"):
        kitti_config({"dst": {"alpha": 2.0}})


def test_real_frames(real_root):
    seq = KittiSequence(real_root, "0003")
    frames = list(convert_sequence(seq))
    assert [f.step for f in frames] == list(range(5, 40, 5))
    moving, static = CLASSES.index("moving"), CLASSES.index("static")
    for f in frames:
        counts = np.bincount(f.labels.ravel(), minlength=256)
        assert counts[moving] > 30  # track 0 (and 1 from frame 22) is always near
        share = np.bincount(f.sensor.ravel(), minlength=3) / f.sensor.size
        assert 0.25 < share[SensorState.FREE] < 0.7 and 0.02 < share[SensorState.OCCUPIED] < 0.12
        # nothing is labelled behind the camera except objects
        assert set(np.unique(f.labels[140:])) <= {moving, static, IGNORE_INDEX}
    assert any(np.bincount(f.labels.ravel(), minlength=256)[static] > 30 for f in frames)
