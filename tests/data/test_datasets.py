"""ShardDataset over stored shards (DataLoader workers, corrupt files)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from torch.utils.data import DataLoader

from dstenv.data.datasets import ShardDataset
from dstenv.data.manifest import write_manifest
from dstenv.data.shards import QUANT_MAX_ERROR, ShardError, ShardWriter


@pytest.fixture
def dataset_dir(tmp_path, make_frame, shard_attrs):
    rng = np.random.default_rng(3)
    frames = {}
    for split, k, n in (("train", 0, 3), ("train", 1, 2), ("val", 0, 2)):
        attrs = dict(shard_attrs, split=split)
        path = tmp_path / split / f"shard-{k:05d}.h5"
        with ShardWriter(path, attrs, masses=True, quantize=False) as w:
            for i in range(n):
                f = make_frame(rng, masses=True, step=i, seed=100 * len(frames) + i)
                w.add(f)
                frames[(split, path.name, i)] = f
    write_manifest(tmp_path)
    return tmp_path, frames


def test_items_match_the_frames(dataset_dir):
    root, frames = dataset_dir
    ds = ShardDataset(root, split="train")
    assert len(ds) == 5
    item = ds[3]  # second shard, frame 0
    f = frames[("train", "shard-00001.h5", 0)]
    assert item["x"].shape == (10, 12, 10) and item["x"].dtype == torch.float32
    np.testing.assert_array_equal(item["x"][:5].numpy(), f.pignistic)
    np.testing.assert_array_equal(item["x"][5:].numpy(), f.pignistic_prev)
    assert item["labels"].dtype == torch.int64 and int(item["labels"][0, 0]) == 255
    assert item["visible"].dtype == torch.bool
    np.testing.assert_array_equal(item["visible"].numpy(), f.visible)
    assert ShardDataset(root, inputs="masses")[0]["x"].shape == (32, 12, 10)
    assert len(ShardDataset(root)) == 7 and len(ShardDataset(root, split="val")) == 2
    with pytest.raises(ValueError, match="unknown inputs 'rgb'"):
        ShardDataset(root, inputs="rgb")


def test_dataloader_with_two_workers(dataset_dir):
    root, _ = dataset_dir
    ds = ShardDataset(root, split="train", inputs="pignistic")
    loader = DataLoader(ds, batch_size=2, num_workers=2, shuffle=False)
    batches = list(loader)
    x = torch.cat([b["x"] for b in batches])
    assert x.shape == (5, 5, 12, 10)
    for i in range(5):
        torch.testing.assert_close(x[i], ds[i]["x"], rtol=0, atol=0)


@pytest.mark.parametrize("quantize", [True, False])
def test_cache_returns_the_same_items_without_reading_again(tmp_path, make_frame, shard_attrs,
                                                            monkeypatch, quantize):
    rng = np.random.default_rng(5)
    path = tmp_path / "shard-00000.h5"
    with ShardWriter(path, dict(shard_attrs, split="train"), quantize=quantize) as w:
        for i in range(3):
            w.add(make_frame(rng, step=i, seed=i))
    plain, cached = ShardDataset(path), ShardDataset(path, cache=True)
    first = [cached[i] for i in range(3)]
    from dstenv.data.reader import ShardReader

    def no_read(*args, **kwargs):
        raise AssertionError("read from disk again")

    monkeypatch.setattr(ShardReader, "get", no_read)
    for i in range(3):
        for key in ("x", "labels", "visible"):
            torch.testing.assert_close(cached[i][key], first[i][key], rtol=0, atol=0)
    monkeypatch.undo()
    for i in range(3):  # dequantised exactly as an uncached read
        torch.testing.assert_close(first[i]["x"], plain[i]["x"], rtol=0, atol=0)
    assert first[0]["x"].dtype == torch.float32
    with pytest.raises(AssertionError, match="again"):
        monkeypatch.setattr(ShardReader, "get", no_read)
        plain[0]


def test_corrupt_shard_raises_or_is_skipped(dataset_dir):
    root, _ = dataset_dir
    bad = root / "train" / "shard-00000.h5"
    bad.write_bytes(bad.read_bytes()[:2000])
    with pytest.raises(ShardError, match=r"train/shard-00000\.h5: not a readable HDF5"):
        ShardDataset([bad, root / "train" / "shard-00001.h5"])
    with pytest.warns(RuntimeWarning, match=r"skipping corrupt shard: .*shard-00000\.h5"):
        ds = ShardDataset([bad, root / "train" / "shard-00001.h5"], on_error="skip")
    assert len(ds) == 2 and ds.files == [root / "train" / "shard-00001.h5"]


def test_quantised_shard_error_bound_through_dataset(tmp_path, make_frame, shard_attrs):
    f = make_frame(np.random.default_rng(9))
    with ShardWriter(tmp_path / "q.h5", shard_attrs) as w:
        w.add(f)
    x = ShardDataset(tmp_path / "q.h5")[0]["x"].numpy()
    assert np.abs(x - f.fcn_input()).max() <= QUANT_MAX_ERROR + 1e-7


def test_corrupt_chunk_at_read_time(tmp_path, make_frame, shard_attrs):
    import h5py

    rng = np.random.default_rng(4)
    frames = [make_frame(rng, step=i) for i in range(3)]
    path = tmp_path / "c.h5"
    with ShardWriter(path, shard_attrs, compression=None) as w:
        for f in frames:
            w.add(f)
    with h5py.File(path) as h:
        offset = h["labels"].id.get_chunk_info(1).byte_offset
    data = bytearray(path.read_bytes())
    data[offset] ^= 0xFF
    path.write_bytes(bytes(data))
    ds = ShardDataset(path)
    expected = sum(np.bincount(f.labels.ravel(), minlength=256)[:5] for f in frames)
    np.testing.assert_array_equal(ds.class_counts, expected)
    ds[0]
    with pytest.raises(ShardError, match=r"c\.h5: frame 1: cannot read 'labels'"):
        ds[1]
    good = tmp_path / "good.h5"
    with ShardWriter(good, shard_attrs) as w:
        w.add(frames[2])
    skipping = ShardDataset([path, good], on_error="skip")
    with pytest.warns(RuntimeWarning, match=r"c\.h5: frame 1"):
        item = skipping[1]  # the damaged shard is dropped: the next readable frame comes
    np.testing.assert_array_equal(item["labels"].numpy(), frames[2].labels)
    # later reads skip the bad shard without reading it again
    np.testing.assert_array_equal(skipping[0]["labels"].numpy(), frames[2].labels)
    with pytest.warns(RuntimeWarning), pytest.raises(ShardError, match="no readable frame"):
        ShardDataset([path], on_error="skip")[1]


def test_sensor_input_and_kitti_labels(dataset_dir):
    """``inputs="fcn10+sensor"`` adds the sensor grid as free / occupied channels;
    ``labels="kitti"`` relabels as a KITTI frame without a map is labelled."""
    from dstenv.data.datasets import network_input, sensor_channels

    root, frames = dataset_dir
    f = frames[("train", "shard-00001.h5", 0)]
    item = ShardDataset(root, split="train", inputs="fcn10+sensor", labels="kitti")[3]
    assert item["x"].shape == (12, 12, 10)
    np.testing.assert_array_equal(item["x"][:10].numpy(),
                                  ShardDataset(root, split="train")[3]["x"].numpy())
    np.testing.assert_array_equal(item["x"][10].numpy(), (f.sensor == 1).astype(np.float32))
    np.testing.assert_array_equal(item["x"][11].numpy(), (f.sensor == 2).astype(np.float32))
    lab = item["labels"].numpy()
    obj = np.isin(f.labels, (3, 4))
    np.testing.assert_array_equal(lab[obj], f.labels[obj])
    assert (lab[~obj & (f.sensor == 1)] == 0).all()  # seen free: navigable
    assert (lab[~obj & (f.sensor != 1)] == 255).all()  # anything else: ignored
    assert (f.labels[~obj & (f.sensor != 1)] != 255).any()  # (something was relabelled)
    # the same channels for a batch of scored frames
    x = np.zeros((2, 10, 12, 10), np.float32)
    both = network_input(x, np.stack([f.sensor, f.sensor]), "fcn10+sensor")
    assert both.shape == (2, 12, 12, 10)
    np.testing.assert_array_equal(both[1, 10:], sensor_channels(f.sensor))
    assert network_input(x, f.sensor[None], "fcn10") is x
    with pytest.raises(ValueError, match="cannot be scored"):
        network_input(x, f.sensor[None], "masses")
    with pytest.raises(ValueError, match="unknown labels 'coco'"):
        ShardDataset(root, labels="coco")


def test_past_rows_find_the_step_one_second_earlier_in_the_same_drive():
    from dstenv.data.datasets import PAST_STEPS, past_rows

    assert PAST_STEPS == 10
    np.testing.assert_array_equal(past_rows(np.arange(13)), [-1] * 10 + [0, 1, 2])
    np.testing.assert_array_equal(past_rows([10, 20, 30]), [-1, 0, 1])  # stride 10
    # a second drive restarts the steps: its frames never reach into the first
    np.testing.assert_array_equal(past_rows([10, 20, 30, 10, 20]), [-1, 0, 1, -1, 3])
    np.testing.assert_array_equal(past_rows([10, 15, 25, 35]), [-1, -1, 1, 2])


def test_past_sensor_is_the_filters_warp():
    from dstenv.data.datasets import past_sensor

    prev = np.random.default_rng(0).integers(0, 3, size=(9, 7)).astype(np.uint8)
    pose = np.array([3.0, -2.0, 0.4])
    np.testing.assert_array_equal(past_sensor(prev, pose, pose, 0.5), prev)
    # two cells forward: what stood two rows ahead is two rows nearer now
    ahead = pose + np.array([1.0 * np.cos(0.4), 1.0 * np.sin(0.4), 0.0])
    out = past_sensor(prev, pose, ahead, 0.5)
    np.testing.assert_array_equal(out[2:], prev[:-2])
    assert (out[:2] == 0).all()  # from outside the earlier grid: unknown


def test_past_input_reads_the_frame_one_second_earlier(tmp_path, make_frame, shard_attrs):
    from dstenv.data.datasets import frame_to_sample, network_input, sensor_channels

    rng = np.random.default_rng(6)
    frames = [make_frame(rng, step=i, seed=4) for i in range(14)]
    for f in frames:
        f.ego_pose = np.array([1.0, 2.0, 0.3])  # a standing ego: the warp is the identity
    path = tmp_path / "shard-00000.h5"
    with ShardWriter(path, dict(shard_attrs, split="train")) as w:
        for f in frames:
            w.add(f)
    ds = ShardDataset(path, inputs="fcn10+sensor+past")
    item = ds[12]
    assert item["x"].shape == (14, 12, 10)
    np.testing.assert_array_equal(item["x"][:12].numpy(),
                                  ShardDataset(path, inputs="fcn10+sensor")[12]["x"].numpy())
    np.testing.assert_array_equal(item["x"][12:].numpy(), sensor_channels(frames[2].sensor))
    assert not ds[9]["x"][12:].any()  # no frame one second earlier: all unknown
    cached = ShardDataset(path, inputs="fcn10+sensor+past", cache=True)
    torch.testing.assert_close(cached[12]["x"], item["x"], rtol=0, atol=0)
    # a batch of scored frames reads the same channels; single frames cannot
    x = np.zeros((1, 10, 12, 10), np.float32)
    got = network_input(x, frames[12].sensor[None], "fcn10+sensor+past", frames[2].sensor[None])
    np.testing.assert_array_equal(got[0, 12:], item["x"][12:].numpy())
    with pytest.raises(ValueError, match="past sensor grids"):
        network_input(x, frames[12].sensor[None], "fcn10+sensor+past")
    with pytest.raises(ValueError, match="earlier frame of the drive"):
        frame_to_sample(frames[12], "fcn10+sensor+past")
    # frames stored 20 steps apart never have one: refused (it trained on blank channels)
    sparse = tmp_path / "sparse" / "shard-00000.h5"
    sparse.parent.mkdir()
    with ShardWriter(sparse, dict(shard_attrs, split="train")) as w:
        for i, f in enumerate(frames[::4]):
            f.step = 20 * i
            w.add(f)
    with pytest.raises(ValueError, match=r"no stored frame has one \(frames 20 steps apart\)"):
        ShardDataset(sparse, inputs="fcn10+sensor+past")
    from dstenv.data.datasets import StreamingDataset

    with pytest.raises(ValueError, match="not a StreamingDataset"):
        StreamingDataset("dense", inputs="fcn10+sensor+past")


def test_a_folder_mixing_two_datasets_is_refused(tmp_path, make_frame, shard_attrs):
    rng = np.random.default_rng(4)

    def shard(path, attrs, h=12, w=10):
        with ShardWriter(path, attrs) as wr:
            wr.add(make_frame(rng, h=h, w=w))

    shard(tmp_path / "train" / "shard-00000.h5", shard_attrs)
    shard(tmp_path / "train" / "shard-00001.h5", shard_attrs)
    assert len(ShardDataset(tmp_path, split="train")) == 2  # no manifest: scanned
    # a shard of another configuration (same geometry) in the folder
    other = {**shard_attrs, "config": {**shard_attrs["config"], "world": {"scenario": "x"}}}
    shard(tmp_path / "train" / "shard-00002.h5", other)
    with pytest.raises(ShardError, match=r"shard-00002\.h5: made with another configuration "
                                         r"than shard-00000\.h5"):
        ShardDataset(tmp_path, split="train")
    # given as a list of files, datasets may be combined: but only of one geometry
    files = sorted((tmp_path / "train").glob("*.h5"))
    assert len(ShardDataset(files)) == 3
    small = {**shard_attrs, "config": {"grid": {"height": 6, "width": 10, "cell_size": 0.5}}}
    shard(tmp_path / "small.h5", small, h=6)
    with pytest.raises(ShardError, match=r"small\.h5: grid 6 x 10 of 0\.5 m, but "
                                         r"shard-00000\.h5 has 12 x 10 of 0\.5 m"):
        ShardDataset([*files, tmp_path / "small.h5"], on_error="skip")


def test_indexing_stops_at_the_end_and_a_typo_split_is_named(dataset_dir):
    root, _ = dataset_dir
    ds = ShardDataset(root, split="train")
    assert len(ds) == 5 and len(list(ds)) == 5  # a plain loop ends
    assert torch.equal(ds[-1]["x"], ds[4]["x"])
    for bad in (5, -6, 10**6):
        with pytest.raises(IndexError, match="out of range for 5 frames"):
            ds[bad]
    for bad in ("0", 1.0, True):
        with pytest.raises(TypeError, match="must be an integer"):
            ds[bad]
    # any integer type (a DataLoader's sampler may hand torch or numpy ones), and locate
    # counts from the end like indexing
    assert torch.equal(ds[torch.tensor(4)]["x"], ds[4]["x"])
    assert torch.equal(ds[np.int16(-1)]["x"], ds[4]["x"])
    assert ds.locate(-1) == ds.locate(4) and ds.locate(np.int64(0))[1] == 0
    with pytest.raises(IndexError, match="out of range for 5 frames"):
        ds.locate(5)
    with pytest.raises(ValueError, match=r"unknown inputs \['fcn10'\]; choose from"):
        ShardDataset(root, split="train", inputs=["fcn10"])
    with pytest.raises(ValueError, match="unknown labels 3; choose from"):
        ShardDataset(root, split="train", labels=3)
    with pytest.raises(TypeError, match="cache must be True or False, got 'yes'"):
        ShardDataset(root, split="train", cache="yes")
    with pytest.raises(ValueError, match=r"no shard of split 'training' .*its splits: train, val"):
        ShardDataset(root, split="training")
    assert len(ShardDataset(root, split="test")) == 0  # a known split may be absent


def test_a_dataset_still_being_written_is_refused(dataset_dir):
    import json
    import os
    import socket

    from dstenv.data.lock import LOCK_NAME

    root, _ = dataset_dir
    (root / LOCK_NAME).write_text(json.dumps({"host": socket.gethostname(), "pid": os.getpid()}))
    with pytest.raises(ValueError, match=r"still being written by pid \d+ on "):
        ShardDataset(root, split="train")
    (root / LOCK_NAME).write_text(json.dumps({"host": socket.gethostname(), "pid": 2**22 + 7}))
    assert len(ShardDataset(root, split="train")) == 5  # its writer is gone: a stale lock


def test_streaming_arguments_are_checked():
    from dstenv.data import StreamingDataset

    for kw, message in (({"seed": -1}, "seed must be an integer >= 0"),
                        ({"seed": "1"}, "seed must be an integer >= 0, got '1'"),
                        ({"rank": -1}, "rank must be an integer >= 0"),
                        ({"max_frames": -1}, "max_frames must be None or an integer >= 1"),
                        ({"max_frames": 1.5}, "max_frames must be None or an integer >= 1"),
                        # at construction, not at the first sample inside a worker
                        ({"split": "validation"}, "unknown split 'validation'"),
                        ({"stride": 0}, "stride must be >= 1"),
                        ({"episode_length": 1}, "keeps no frame after a warmup")):
        with pytest.raises(ValueError, match=message):
            StreamingDataset("default", **kw)


def test_training_data_of_shards_names_files_sizes_and_cells(dataset_dir):
    from dstenv.segment.checkpoint import training_data

    root, _ = dataset_dir
    ident = training_data(ShardDataset(root, split="train"))
    assert ident["cell_size"] == 0.5 and ident["frames"] == 5
    assert [f for f, _ in ident["shards"]] == ["train/shard-00000.h5", "train/shard-00001.h5"]
    assert ident != training_data(ShardDataset(root, split="val"))


def test_set_epoch_takes_an_integer_at_least_zero():
    """Attack 16: set_epoch(1.7) ran as epoch 1; -1 failed later inside numpy."""
    from dstenv.data import StreamingDataset

    ds = StreamingDataset(seed=0)
    for bad in (-1, 1.7, "2", True):
        with pytest.raises(ValueError, match=r"set_epoch: an integer >= 0, got"):
            ds.set_epoch(bad)
    ds.set_epoch(3)
    assert ds.epoch == 3


def test_a_shard_replaced_after_the_dataset_was_opened_is_refused(dataset_dir, tmp_path):
    """Attack 17: shards replaced under a running train were read as the ones counted."""
    import os
    import pickle
    import shutil

    root, _ = dataset_dir
    ds = ShardDataset(root, split="train")
    first, k = ds.locate(0)
    copy = tmp_path / "other.h5"
    shutil.copyfile(first, copy)
    os.replace(copy, first)  # the same bytes, another file (a rewrite)
    worker = pickle.loads(pickle.dumps(ds))  # as a DataLoader worker opens it
    with pytest.raises(ShardError, match=r"changed since this dataset was opened"):
        worker[0]
    assert len(ShardDataset(root, split="train")[0]["x"])  # opened again: fine
