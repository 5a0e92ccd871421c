"""export-kitti: a simulated drive read back by the KITTI readers and converter."""

from __future__ import annotations

import numpy as np
import pytest

from dstenv.data.sampling import scenario_config
from dstenv.dst import CLASSES
from dstenv.kitti.export import export_drive, sim_calibration
from dstenv.kitti.objects import boxes_in_velodyne
from dstenv.kitti.readers import read_calib
from dstenv.kitti.sequence import KittiSequence, convert_sequence
from dstenv.sensing.labels import label_grid

STATIC, MOVING = CLASSES.index("static"), CLASSES.index("moving")
FAST = {"lidar": {"hdl64": {"azimuth_step": 0.7}}, "grid": {"height": 96, "width": 96}}


@pytest.fixture(scope="module")
def drive(tmp_path_factory):
    """Six frames of the clean scenario, exported, with the simulator's own state."""
    from dstenv.pipeline import Pipeline

    root = tmp_path_factory.mktemp("sim-kitti")
    cfg = scenario_config("clean", FAST)  # the ideal world: seed 2 has cars in view
    export_drive(cfg, seed=2, frames=6, out=root, sequence=7)
    pipe = Pipeline({**cfg, "lidar": {**cfg["lidar"], "model": "hdl64"}})
    worlds = []
    for f in range(6):
        frame = pipe.reset(2) if f == 0 else pipe.step()
        a = pipe.world.agents
        worlds.append((frame.ego_pose.copy(), a.xy.copy(), a.yaw.copy(), a.speed.copy(),
                       a.length.copy(), a.width.copy(), a.height.copy(), a.kind.copy(),
                       a.parked.copy()))
    return root, worlds, pipe


def test_files_read_back_exactly(drive):
    root, worlds, _ = drive
    seq = KittiSequence(root, 7)
    assert seq.n_frames == 6
    calib = read_calib(root / "training" / "calib" / "0007.txt")
    np.testing.assert_allclose(calib.velo_to_rect, sim_calibration().velo_to_rect, atol=1e-12)
    # poses: the devkit trajectory is the simulated one, translated to start at 0
    sim = np.array([w[0] for w in worlds])
    np.testing.assert_allclose(seq.trajectory.poses[:, :2], sim[:, :2] - sim[0, :2], atol=2e-3)
    np.testing.assert_allclose(seq.trajectory.poses[:, 2], sim[:, 2], atol=1e-6)
    # scans: float32 x, y, z, r rows, the road 1.73 m below the sensor, kerbs 0.12 m up
    pts = seq.scan(0)
    assert pts.shape[1] == 4 and pts.dtype == np.float32
    assert (np.abs(pts[:, 2] + 1.73) < 0.05).mean() > 0.2
    assert (np.abs(pts[:, 2] + 1.61) < 0.05).mean() > 0.05
    # boxes: every written agent comes back at its simulated place, size and heading
    boxes = boxes_in_velodyne(seq.labels, seq.calib)
    assert len(boxes) > 0
    for f in range(6):
        ego, xy, yaw, _, length, width, height, _, _ = worlds[f]
        c, s = np.cos(ego[2]), np.sin(ego[2])
        d = xy - ego[:2]
        local = np.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]], axis=1)
        sel = boxes.frame == f
        k = boxes.track[sel]
        np.testing.assert_allclose(boxes.centre[sel, :2], local[k], atol=1e-4)
        np.testing.assert_allclose(boxes.length[sel], length[k], atol=1e-5)
        np.testing.assert_allclose(boxes.height[sel], height[k], atol=1e-5)
        dyaw = (boxes.yaw[sel] - (yaw[k] - ego[2]) + np.pi) % (2 * np.pi) - np.pi
        np.testing.assert_allclose(dyaw, 0.0, atol=1e-5)
        assert np.all(local[k, 0] > 0)  # only agents in front of the camera


def test_convert_gives_the_simulators_labels(drive):
    """kitti convert labels the written agents' cells as the simulator does.

    The rules differ only where documented: KITTI's ``paper`` rule (10 cm between
    10 Hz frames, i.e. 1 m/s) against the simulator's speed threshold set to 1 m/s,
    and only agents in the camera image are labelled.
    """
    root, worlds, pipe = drive
    seq = KittiSequence(root, 7)
    from dstenv.grid import GridSpec

    spec = GridSpec(256, 256, 0.33)
    cfg = {"grid": {"height": 256, "width": 256, "cell_size": 0.33}, "stride": 1, "warmup": 0,
           "labels": {"rule": "paper"}}
    frames = list(convert_sequence(seq, cfg))
    assert [f.step for f in frames] == list(range(6))
    from dstenv.sim.types import Agents

    compared = 0
    for f, fr in zip(range(6), frames):
        ego, xy, yaw, speed, length, width, height, kind, parked = worlds[f]
        written = np.unique(seq.boxes.track[seq.boxes.frame == f])
        if f == 0:  # the paper rule looks at the next frame first: skip the start
            continue
        steady = np.abs(speed[written] - 1.0) > 0.3  # far from the 1 m/s threshold
        keep = written[steady]
        agents = Agents(xy[keep], yaw[keep], speed[keep], length[keep], width[keep],
                        kind[keep], parked[keep], height[keep])
        own = label_grid(pipe.world.map, agents, ego, spec, 1.0)
        for cls in (STATIC, MOVING):
            mine = own == cls
            theirs = fr.labels == cls
            compared += int(mine.sum())
            assert np.array_equal(mine & theirs, mine), (f, cls, int((mine & ~theirs).sum()))
    assert compared > 30  # seed 2: two parked cars and a moving one in view


def test_export_never_writes_over_or_beside_a_sequence(drive, tmp_path):
    root, _, _ = drive
    split = root / "training"
    before = {p: p.stat().st_mtime_ns for p in split.rglob("*") if p.is_file()}
    with pytest.raises(FileExistsError, match="already holds sequence 0007"):
        export_drive(scenario_config("clean", FAST), seed=3, frames=2, out=root, sequence=7)
    assert {p: p.stat().st_mtime_ns for p in split.rglob("*") if p.is_file()} == before
    # a sequence whose scans alone exist (a real one without labels, say) is refused too
    (split / "velodyne" / "0009").mkdir()
    with pytest.raises(FileExistsError, match="velodyne/0009"):
        export_drive(scenario_config("clean", FAST), seed=3, frames=2, out=root, sequence=9)
    with pytest.raises(ValueError, match="0..9999"):
        export_drive(scenario_config("clean", FAST), seed=3, frames=2, out=tmp_path,
                     sequence=10000)
    # a killed export's staging folder is cleared; the sequence appears whole
    stage = tmp_path / "training" / ".export-0001.partial" / "velodyne"
    stage.mkdir(parents=True)
    (stage / "000005.bin").write_bytes(b"stale")
    export_drive(scenario_config("clean", FAST), seed=3, frames=2, out=tmp_path, sequence=1)
    scans = sorted(p.name for p in (tmp_path / "training" / "velodyne" / "0001").iterdir())
    assert scans == ["000000.bin", "000001.bin"]
    assert not (tmp_path / "training" / ".export-0001.partial").exists()
    for d in ("oxts", "calib", "label_02"):
        assert (tmp_path / "training" / d / "0001.txt").is_file()


def test_export_cli_refuses_a_seed_out_of_range_and_a_file_as_out(tmp_path, capsys):
    from dstenv.cli import main

    (tmp_path / "f.png").write_bytes(b"x")
    for argv, message in ((["--seed", str(2**64)], "--seed must be in [0, 2**63)"),
                          (["--seed", "-5"], "--seed must be in [0, 2**63), got -5"),
                          (["--out", str(tmp_path / "f.png")], "is a file; give a folder")):
        args = ["export-kitti", "--frames", "2", "--out", str(tmp_path / "k"), *argv]
        assert main(args) == 2
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1
    assert not (tmp_path / "k").exists()
