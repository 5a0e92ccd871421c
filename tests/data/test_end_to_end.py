"""The real Pipeline through generation, the CLI, the datasets and Ray (tiny config)."""

from __future__ import annotations

import hashlib

import numpy as np
import pytest
import torch
from torch.utils.data import DataLoader

from dstenv.cli import main
from dstenv.data.datasets import ShardDataset, StreamingDataset
from dstenv.data.manifest import load_manifest
from dstenv.data.sampling import split_of_seed
from dstenv.data.shards import ShardReader

TINY = {
    "grid": {"height": 32, "width": 32},
    "lidar": {"beams": 180},
    "world": {"map": {"blocks_x": 2, "blocks_y": 2},
              "traffic": {"cars": 3, "cyclists": 1, "pedestrians": 2}},
}
TINY_ARGS = ["--grid", "32", "--set", "lidar.beams=180", "--set", "world.map.blocks_x=2",
             "--set", "world.map.blocks_y=2", "--set", "world.traffic.cars=3",
             "--set", "world.traffic.cyclists=1", "--set", "world.traffic.pedestrians=2",
             "--episode-length", "7", "--stride", "3", "--frames-per-shard", "2", "--quiet"]


def _digests(root):
    return {p.relative_to(root).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


def test_generate_cli_real_pipeline_is_deterministic(tmp_path):
    for name in ("a", "b"):
        args = ["generate", "--frames", "3", "--out", str(tmp_path / name), "--seed", "4",
                "--split", "test", "--masses", *TINY_ARGS]
        assert main(args) == 0
    assert _digests(tmp_path / "a") == _digests(tmp_path / "b")
    m = load_manifest(tmp_path / "a", verify="hash")
    assert m["frames"] == 3 and m["grid_shape"] == [32, 32] and m["cell_size"] == 0.33
    assert m["meta"]["config"]["lidar"]["beams"] == 180
    ds = ShardDataset(tmp_path / "a", split="test", inputs="masses")
    item = ds[2]
    assert item["x"].shape == (32, 32, 32)
    np.testing.assert_allclose(item["x"].sum(0).numpy(), 1.0, atol=1e-4)  # masses sum to 1
    fcn = ShardDataset(tmp_path / "a")[0]
    assert fcn["x"].shape == (10, 32, 32) and fcn["labels"].max() <= 4
    np.testing.assert_allclose(fcn["x"][:5].sum(0).numpy(), 1.0, atol=5 / 510 + 1e-6)
    with ShardReader(tmp_path / "a" / "test" / "shard-00000.h5") as r:
        f = r[0]
        assert f.step == 3 and split_of_seed(f.seed) == "test"
        assert np.array_equal(f.visible, f.sensor != 0)


def test_cli_errors_are_one_line(tmp_path, capsys):
    assert main(["generate", "--frames", "2", "--out", str(tmp_path), "--scenario",
                 "no_such_scenario"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "unknown scenario 'no_such_scenario'" in err
    assert main(["generate", "--frames", "2", "--out", str(tmp_path), "--set",
                 "world.bogus=1"]) == 2
    assert "unknown key 'bogus'" in capsys.readouterr().err
    blocker = tmp_path / "file"
    blocker.write_text("")
    assert main(["generate", "--frames", "2", "--out", str(blocker / "x"), *TINY_ARGS]) == 2
    assert "/x: cannot create its folder (" in capsys.readouterr().err
    assert main(["generate", "--frames", "2", "--out", str(tmp_path / "y"), "--stride", "50",
                 "--episode-length", "20"]) == 2
    assert "keeps no frame" in capsys.readouterr().err
    assert not (tmp_path / "y").exists() or not list((tmp_path / "y").rglob("*.h5"))


def test_streaming_workers_yield_different_frames():
    ds = StreamingDataset(TINY, seed=3, episode_length=7, stride=3, max_frames=2)
    loader = DataLoader(ds, batch_size=None, num_workers=2)
    items = list(loader)
    assert len(items) == 4  # 2 workers x 2 frames, interleaved w0, w1, w0, w1
    assert items[0]["x"].shape == (10, 32, 32) and items[0]["labels"].dtype == torch.int64
    assert not torch.equal(items[0]["x"], items[1]["x"])
    again = list(DataLoader(ds, batch_size=None, num_workers=2))
    assert all(torch.equal(a["x"], b["x"]) for a, b in zip(items, again))  # reproducible
    ds.set_epoch(1)
    assert not torch.equal(next(iter(ds))["x"], items[0]["x"])


def test_episodes_per_map_cli_and_streaming(tmp_path):
    common = ["--frames", "6", "--seed", "4", "--split", "train", *TINY_ARGS,
              "--frames-per-shard", "6", "--episodes-per-map", "3"]
    assert main(["generate", "--out", str(tmp_path / "a"), *common]) == 0
    with ShardReader(tmp_path / "a" / "train" / "shard-00000.h5") as r:
        seeds = [int(r[i].seed) for i in range(len(r))]
        steps = [int(r[i].step) for i in range(len(r))]
        assert r.attrs["task"]["episodes_per_map"] == 3
    # 2 kept steps per episode (3, 6), 3 episodes on the first map
    assert steps == [3, 6] * 3 and len(set(seeds)) == 1
    assert main(["generate", "--out", str(tmp_path / "b"), *common]) == 0
    assert _digests(tmp_path / "a") == _digests(tmp_path / "b")
    ds = StreamingDataset(TINY, seed=3, episode_length=7, stride=3, max_frames=4,
                          episodes_per_map=2)
    assert len(list(ds)) == 4


def test_worker_pool_matches_serial(tmp_path):
    common = ["--frames", "4", "--seed", "2", "--split", "train", *TINY_ARGS]
    assert main(["generate", "--out", str(tmp_path / "serial"), *common]) == 0
    assert main(["generate", "--out", str(tmp_path / "pool"), "--workers", "2", *common]) == 0
    assert _digests(tmp_path / "serial") == _digests(tmp_path / "pool")


@pytest.mark.slow
def test_ray_local_matches_serial(tmp_path):
    pytest.importorskip("ray")
    common = ["--frames", "4", "--seed", "2", "--split", "val", *TINY_ARGS]
    assert main(["generate", "--out", str(tmp_path / "serial"), *common]) == 0
    assert main(["generate", "--out", str(tmp_path / "ray"), "--ray", "--workers", "2",
                 *common]) == 0
    assert _digests(tmp_path / "serial") == _digests(tmp_path / "ray")
