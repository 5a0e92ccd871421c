"""Which files make a ShardDataset: attack 16's empty folder, empty list and a file twice
were datasets of 0 (or double-counted) frames."""

import pytest

from dstenv.data import ShardDataset
from dstenv.data.generate import GenerateSpec, generate
from dstenv.data.shardfiles import resolve_files


@pytest.fixture
def dataset(tmp_path, fake_pipeline):
    spec = GenerateSpec(config={"grid": {"height": 8, "width": 6, "cell_size": 0.5}}, frames=4,
                        frames_per_shard=2, episode_length=5, stride=2, warmup=0, split="train")
    generate(spec, tmp_path / "d", progress=False)
    return tmp_path / "d"


def test_a_dataset_resolves_to_its_listed_shards(dataset):
    files = resolve_files(dataset, "train")
    assert [p.name for p, _ in files] == ["shard-00000.h5", "shard-00001.h5"]
    assert [n for _, n in files] == [2, 2]  # frame counts from the manifest
    assert resolve_files(dataset, "val") == []  # a split it does not have: none
    assert resolve_files(files[0][0], None) == [(files[0][0], None)]


def test_empty_or_repeated_inputs_are_refused(dataset, tmp_path):
    (tmp_path / "empty").mkdir()
    one = dataset / "train" / "shard-00000.h5"
    for bad, message in ((tmp_path / "empty", r"empty: no manifest\.json and no shard files"),
                         ([], "a non-empty list of shard files, got \\[\\]"),
                         (5, "got 5"),
                         ([one, one], r"shard-00000\.h5 is listed twice"),
                         ([one, one.parent / ".." / "train" / one.name],  # another spelling
                          r"shard-00000\.h5 is listed twice")):
        with pytest.raises(ValueError, match=message):
            ShardDataset(bad)
    with pytest.raises(FileNotFoundError, match="no such dataset directory"):
        ShardDataset(tmp_path / "nowhere")
    assert len(ShardDataset(dataset, split="val")) == 0  # an absent known split: allowed
    assert len(ShardDataset([one])) == 2
