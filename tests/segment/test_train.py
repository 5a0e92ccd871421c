import pytest
import torch

from dstenv.config import ConfigError
from dstenv.segment.checkpoint import load_checkpoint, load_segmenter
from dstenv.segment.evaluate import batches, evaluate
from dstenv.segment.registry import create_segmenter
from dstenv.segment.train import train

SMALL = {
    "model": "unet-light",
    "model_kwargs": {"base": 4, "depth": 2},
    "batch_size": 4,
    "lr": 5e-3,
}


def _weights(seg):
    return {k: v.clone() for k, v in seg.model.state_dict().items()}


def test_same_seed_same_weights_and_resume_matches(tmp_path, make_frames):
    data, val = make_frames(8, seed=1), make_frames(4, seed=2)
    quiet = {"progress": False, "log": lambda m: None}
    a, ha = train({**SMALL, "epochs": 2}, data, val, tmp_path / "a", **quiet)
    b, _ = train({**SMALL, "epochs": 2}, data, val, tmp_path / "b", **quiet)
    wa, wb = _weights(a), _weights(b)
    assert all(torch.equal(wa[k], wb[k]) for k in wa)
    # one epoch, then resume for the second: same weights as straight through
    train({**SMALL, "epochs": 1}, data, val, tmp_path / "c", **quiet)
    c, hc = train({**SMALL, "epochs": 2}, data, val, tmp_path / "c", **quiet)
    wc = _weights(c)
    assert all(torch.equal(wa[k], wc[k]) for k in wa)
    assert hc["epoch"] == [1, 2] and hc["train_loss"] == ha["train_loss"]
    ckpt = load_checkpoint(tmp_path / "c" / "last.pt")
    assert ckpt["epoch"] == 1 and ckpt["config"]["model_kwargs"] == {"base": 4, "depth": 2}
    assert len(ckpt["config"]["class_weights"]) == 5
    # a different seed gives different weights
    d, _ = train({**SMALL, "epochs": 1, "seed": 5}, data, None, None, **quiet)
    assert not all(torch.equal(wa[k], _weights(d)[k]) for k in wa)


def test_resume_with_other_settings_is_refused(tmp_path, make_frames):
    data = make_frames(4, seed=1)
    train({**SMALL, "epochs": 1}, data, None, tmp_path, progress=False, log=lambda m: None)
    with pytest.raises(ConfigError, match="lr"):
        train(
            {**SMALL, "epochs": 2, "lr": 1e-2},
            data,
            None,
            tmp_path,
            progress=False,
            log=lambda m: None,
        )


def test_resume_on_other_data_is_refused(tmp_path, make_frames):
    from dstenv.segment.checkpoint import training_data

    data, other = make_frames(4, seed=1), make_frames(4, seed=2)
    quiet = {"progress": False, "log": lambda m: None}
    ident = {"source": "shards in a", "frames": 4, "shards": [["train/shard-00000.h5", 100]]}
    train({**SMALL, "epochs": 1}, data, None, tmp_path, data_id=ident, **quiet)
    assert load_checkpoint(tmp_path / "last.pt")["data"] == ident
    moved = {**ident, "shards": [["train/shard-00000.h5", 101]]}
    with pytest.raises(ConfigError, match=r"trained on other data \(shards differ"):
        train({**SMALL, "epochs": 2}, other, None, tmp_path, data_id=moved, **quiet)
    _, h = train({**SMALL, "epochs": 2}, data, None, tmp_path, data_id=ident, **quiet)
    assert h["epoch"] == [1, 2]  # the same data resumes
    # the identity of a stream: its configuration, seed, split and sampling
    from dstenv.data import StreamingDataset

    a, b = StreamingDataset("dense", seed=0), StreamingDataset("dense", seed=1)
    assert training_data(a) == training_data(StreamingDataset("dense", seed=0))
    assert training_data(a) != training_data(b)
    assert training_data(a)["config"] != training_data(StreamingDataset("default"))["config"]


def test_a_checkpoint_knows_its_cells_and_a_mismatch_is_noted(tmp_path, make_frames):
    from dstenv.segment.checkpoint import load_segmenter
    from dstenv.segment.plan import resolution_note

    ident = {"source": "shards in a", "frames": 4, "cell_size": 0.5, "shards": []}
    train({**SMALL, "epochs": 1}, make_frames(4), None, tmp_path, data_id=ident,
          progress=False, log=lambda m: None)
    seg = load_segmenter(tmp_path / "best.pt")
    assert seg.trained_cell_size == 0.5
    seg.checkpoint = "best.pt"
    assert resolution_note(seg, 0.5) is None
    assert resolution_note(seg, 0.33) == (
        "note: best.pt was trained on cells of 0.5 m, these drives have 0.33 m: its scores "
        "are of a network used at another resolution")
    seg.trained_cell_size = None  # a checkpoint from before: nothing to compare
    assert resolution_note(seg, 0.33) is None


@pytest.mark.parametrize("over, message", [
    ({"weight_power": float("nan")}, "train.weight_power must be a finite number >= 0, got nan"),
    ({"lr": float("inf")}, "train.lr must be a finite number > 0, got inf"),
    ({"crop": -3}, "train.crop must be an integer >= 0"),
    ({"class_weights": [1, 1, float("nan"), 1, 1]}, "need finite values >= 0"),
    ({"class_weights": [-1, 1, 1, 1, 1]}, "need finite values >= 0"),
    ({"class_weights": [0, 0, 0, 0, 0]}, "not all 0"),
    ({"flip": 1.5}, r"train.flip must be in \[0, 1\], got 1.5"),
    ({"flip": float("nan")}, r"train.flip must be in \[0, 1\]"),
])
def test_nan_negative_or_zero_weights_are_refused(make_frames, tmp_path, over, message):
    # a NaN weight trained to NaN weights and still exited 0
    with pytest.raises(ConfigError, match=message):
        train({**SMALL, **over}, make_frames(2), None, tmp_path, progress=False)
    assert not list(tmp_path.iterdir())


def test_a_damaged_last_checkpoint_says_how_to_start_over(tmp_path, make_frames):
    (tmp_path / "last.pt").write_bytes(b"not a checkpoint")
    with pytest.raises(ValueError, match="cannot read checkpoint.*start over with --no-resume"):
        train({**SMALL, "epochs": 1}, make_frames(2), None, tmp_path, progress=False)
    train({**SMALL, "epochs": 1}, make_frames(2), None, tmp_path, resume=False, progress=False,
          log=lambda m: None)


def test_an_unknown_device_is_one_line():
    from dstenv.segment.train import resolve_device

    with pytest.raises(ConfigError, match="device 'foo': not a torch device; use auto, cpu"):
        resolve_device("foo")
    assert resolve_device("cpu").type == "cpu"


def test_bad_config_names_the_key(make_frames):
    with pytest.raises(ConfigError, match="unknown key 'epoch'"):
        train({"epoch": 3}, make_frames(2), progress=False)
    with pytest.raises(ConfigError, match="unknown model"):
        train({"model": "resnet"}, make_frames(2), progress=False)


def test_training_beats_noisy_argmax(tmp_path, make_frames):
    # the synthetic input is a noisy softmax of the labels: a trained net denoises it
    data, test = make_frames(24, seed=3), make_frames(6, seed=4)
    seg, hist = train(
        {**SMALL, "model_kwargs": {"base": 8, "depth": 2}, "epochs": 6, "loss": "wce+lovasz"},
        data,
        test,
        tmp_path,
        progress=False,
        log=lambda m: None,
    )
    assert hist["train_loss"][-1] < hist["train_loss"][0]
    best = load_segmenter(tmp_path / "best.pt")
    learned = evaluate(best, batches(test, 6))
    dst = evaluate(create_segmenter("dst"), batches(test, 6))
    from dstenv.segment.metrics import mean_iou

    assert mean_iou(learned.all) > mean_iou(dst.all) + 0.05


def test_weight_power_softens_median_frequency_weights(tmp_path, make_frames):
    data = make_frames(4, seed=1)
    quiet = {"progress": False, "log": lambda m: None}
    train({**SMALL, "epochs": 1}, data, None, tmp_path / "a", **quiet)
    train({**SMALL, "epochs": 1, "weight_power": 0.5}, data, None, tmp_path / "b", **quiet)
    wa = load_checkpoint(tmp_path / "a" / "last.pt")["config"]["class_weights"]
    wb = load_checkpoint(tmp_path / "b" / "last.pt")["config"]["class_weights"]
    assert wb == pytest.approx([w**0.5 for w in wa], rel=1e-6)
    assert max(wa) > 1.5  # the rare synthetic classes are up-weighted


def test_streaming_training_without_disk():
    from dstenv.data import StreamingDataset

    stream = StreamingDataset(
        {"grid": {"height": 32, "width": 32}}, seed=0, episode_length=12, stride=4, warmup=4
    )
    quiet = {"progress": False, "log": lambda m: None}
    with pytest.raises(ConfigError, match="max_batches"):
        train({**SMALL, "epochs": 1}, stream, **quiet)
    with pytest.raises(ConfigError, match="class_weights"):
        train({**SMALL, "epochs": 1, "max_batches": 2}, stream, **quiet)
    seg, hist = train(
        {**SMALL, "epochs": 2, "max_batches": 2, "class_weights": [1.0] * 5}, stream, **quiet
    )
    assert hist["epoch"] == [1, 2] and all(v > 0 for v in hist["train_loss"])


def test_init_starts_from_a_checkpoint(tmp_path, make_frames):
    """train --init: fine-tuning continues the checkpoint's weights (lr 0 keeps them)."""
    data = make_frames(4, seed=1)
    quiet = {"progress": False, "log": lambda m: None}
    a, _ = train({**SMALL, "epochs": 1}, data, None, tmp_path / "a", **quiet)
    frozen = {**SMALL, "epochs": 1, "lr": 1e-12, "seed": 7, "init": str(tmp_path / "a" / "last.pt")}
    b, _ = train(frozen, make_frames(4, seed=3), None, tmp_path / "b", **quiet)
    # parameters kept (batch-norm running statistics follow the new frames)
    pa, pb = dict(a.model.named_parameters()), dict(b.model.named_parameters())
    assert all(torch.allclose(pa[k], pb[k], atol=1e-6) for k in pa)
    fresh, _ = train({**frozen, "init": ""}, make_frames(4, seed=3), None, None, **quiet)
    first = next(iter(pa))  # without --init: another (seed 7) random start
    assert not torch.allclose(pa[first], dict(fresh.model.named_parameters())[first])
    other = {**frozen, "model_kwargs": {"base": 8, "depth": 2}}
    with pytest.raises(ConfigError, match="train.init: .*model_kwargs"):
        train(other, data, None, None, **quiet)


def test_fixed_batches_draws_the_same_steps_from_any_data_size(tmp_path, make_frames):
    class Counting(torch.utils.data.Dataset):
        def __init__(self, frames):
            self.frames, self.calls = frames, 0

        def __len__(self):
            return len(self.frames)

        def __getitem__(self, i):
            self.calls += 1
            return self.frames[i]

    quiet = {"progress": False, "log": lambda m: None}
    cfg = {**SMALL, "epochs": 2, "fixed_batches": 3, "class_weights": [1.0] * 5}
    for n in (2, 9):  # fewer frames than one batch, and more than three batches' worth
        data = Counting(make_frames(n, seed=1))
        train(cfg, data, None, None, **quiet)
        # one sample read to size the model, then 2 epochs x 3 batches x 4 frames
        assert data.calls == 1 + 2 * 3 * 4
    with pytest.raises(ConfigError, match="fixed_batches"):
        train({**cfg, "fixed_batches": -1}, make_frames(2), progress=False)


def test_best_checkpoint_without_validation_follows_the_training_loss(tmp_path, make_frames):
    """Regression: without validation data best.pt was only written once the training
    loss fell below 1 (the best score started at -1 instead of -inf)."""
    quiet = {"progress": False, "log": lambda m: None}
    cfg = {**SMALL, "epochs": 2, "lr": 1e-12, "loss": "wce+lovasz"}  # the loss stays > 1
    _, hist = train(cfg, make_frames(4, seed=1), None, tmp_path, **quiet)
    assert min(hist["train_loss"]) > 1 and hist["val_miou"] == [None, None]
    best = load_checkpoint(tmp_path / "best.pt")
    assert best["epoch"] == min(range(2), key=lambda e: hist["train_loss"][e])


def test_inputs_are_recorded_checked_and_loaded(tmp_path, make_frames):
    """train.inputs names what ``x`` holds: checked against the data, kept in the
    checkpoint's spec, rebuilt by load_segmenter, and checked by load_checkpoints."""
    from dstenv.segment.evaluate import load_checkpoints

    quiet = {"progress": False, "log": lambda m: None}
    data = make_frames(4, seed=1)
    with pytest.raises(ConfigError, match="train.inputs is 'fcn10\\+sensor' \\(12 channels\\) "
                                          "but the training data gives 10"):
        train({**SMALL, "epochs": 1, "inputs": "fcn10+sensor"}, data, None, None, **quiet)
    with pytest.raises(ConfigError, match="train.labels: unknown labels 'coco'"):
        train({**SMALL, "labels": "coco"}, data, None, None, **quiet)
    sensor = [{**s, "x": torch.cat([s["x"], torch.zeros(2, *s["x"].shape[1:])])} for s in data]
    train({**SMALL, "epochs": 1, "inputs": "fcn10+sensor", "labels": "kitti"}, sensor, None,
          tmp_path / "s", **quiet)
    seg = load_segmenter(tmp_path / "s" / "last.pt")
    assert seg.inputs == "fcn10+sensor" and seg.spec()["in_channels"] == 12
    assert load_checkpoint(tmp_path / "s" / "last.pt")["config"]["labels"] == "kitti"
    # scored on BetP data (10 channels), the sensor channels come from the drives
    (loaded,) = load_checkpoints([tmp_path / "s" / "last.pt"], 10)
    assert loaded.inputs == "fcn10+sensor"
    with pytest.raises(ValueError, match="takes 12 input channels \\(fcn10\\+sensor\\) but the "
                                         "data gives 5"):
        load_checkpoints([tmp_path / "s" / "last.pt"], 5)
    # a checkpoint written before inputs were recorded reads as fcn10 and can start a
    # fine-tuning
    train({**SMALL, "epochs": 1}, data, None, tmp_path / "old", **quiet)
    ckpt = torch.load(tmp_path / "old" / "last.pt", weights_only=True)
    del ckpt["spec"]["inputs"]
    torch.save(ckpt, tmp_path / "old" / "last.pt")
    assert load_segmenter(tmp_path / "old" / "last.pt").inputs == "fcn10"
    train({**SMALL, "epochs": 1, "init": str(tmp_path / "old" / "last.pt")}, data, None, None,
          **quiet)


def test_flip_changes_training_and_stays_seeded(tmp_path, make_frames):
    data = make_frames(8, seed=1)
    quiet = {"progress": False, "log": lambda m: None}
    a, _ = train({**SMALL, "epochs": 1}, data, None, None, **quiet)
    b, _ = train({**SMALL, "epochs": 1, "flip": 0.5}, data, None, None, **quiet)
    c, _ = train({**SMALL, "epochs": 1, "flip": 0.5}, data, None, None, **quiet)
    wa, wb, wc = _weights(a), _weights(b), _weights(c)
    assert not all(torch.equal(wa[k], wb[k]) for k in wa)
    assert all(torch.equal(wb[k], wc[k]) for k in wb)


def test_a_kill_between_the_two_checkpoints_resumes_to_the_same_files(tmp_path, make_frames,
                                                                      monkeypatch):
    """best.pt is written before last.pt: a run killed between them redoes that epoch."""
    import dstenv.segment.train as train_mod

    data, val = make_frames(8, seed=1), make_frames(4, seed=2)
    quiet = {"progress": False, "log": lambda m: None}
    train({**SMALL, "epochs": 2}, data, val, tmp_path / "whole", **quiet)
    real_save, calls = train_mod.save_checkpoint, []

    def dying(path, payload):  # dies when epoch 2 (index 1) would write last.pt
        calls.append((path.name, payload["epoch"]))
        if path.name == "last.pt" and payload["epoch"] == 1:
            raise KeyboardInterrupt
        return real_save(path, payload)

    monkeypatch.setattr(train_mod, "save_checkpoint", dying)
    with pytest.raises(KeyboardInterrupt):
        train({**SMALL, "epochs": 2}, data, val, tmp_path / "cut", **quiet)
    assert ("best.pt", 0) in calls and calls.index(("best.pt", 0)) < calls.index(("last.pt", 0))
    monkeypatch.setattr(train_mod, "save_checkpoint", real_save)
    train({**SMALL, "epochs": 2}, data, val, tmp_path / "cut", **quiet)
    for name in ("best.pt", "last.pt"):
        a, b = (load_checkpoint(tmp_path / d / name) for d in ("whole", "cut"))
        assert a["epoch"] == b["epoch"] and a["history"] == b["history"]
        assert all(torch.equal(a["model"][k], b["model"][k]) for k in a["model"])


def test_a_fine_tuning_knows_its_start_by_content(tmp_path, make_frames):
    from dstenv.segment.train import start_changed

    data = make_frames(4, seed=1)
    quiet = {"progress": False, "log": lambda m: None}
    train({**SMALL, "epochs": 1}, data, None, tmp_path / "a", **quiet)
    start = tmp_path / "a" / "best.pt"
    tune = {**SMALL, "epochs": 1, "init": str(start)}
    train(tune, data, None, tmp_path / "b", **quiet)
    assert not start_changed(tmp_path / "b", start) and not start_changed(tmp_path / "x", start)
    # the start moved with its folder: the same weights, resumes
    moved = tmp_path / "moved"
    (tmp_path / "a").rename(moved)
    assert not start_changed(tmp_path / "b", moved / "best.pt")
    train({**tune, "epochs": 2, "init": str(moved / "best.pt")}, data, None, tmp_path / "b",
          **quiet)
    # the start trained further: other weights, named; start_changed says so
    train({**SMALL, "epochs": 2}, data, None, moved, **quiet)
    assert start_changed(tmp_path / "b", moved / "best.pt")
    with pytest.raises(ConfigError, match="started from other weights than train.init"):
        train({**tune, "epochs": 3, "init": str(moved / "best.pt")}, data, None, tmp_path / "b",
              **quiet)


def test_a_nan_loss_stops_training_before_any_checkpoint(tmp_path, make_frames):
    """Shards whose inputs decode to NaN (a prob_scale of 0) trained to NaN weights and
    saved them, with exit 0 (attack 14)."""
    data = make_frames(8, seed=1)
    data.items[5]["x"][0, 3, 3] = float("nan")
    with pytest.raises(ValueError, match=r"the loss is nan at epoch 1, batch \d: an input "
                                         r"holds NaN or inf \(check the data"):
        train({**SMALL, "epochs": 2, "class_weights": [1.0] * 5}, data, None, tmp_path / "m",
              progress=False, log=lambda m: None)
    assert not list((tmp_path / "m").glob("*.pt"))


def test_a_failed_cli_training_leaves_no_empty_folder(tmp_path, capsys, monkeypatch):
    import dstenv.segment.train as train_module
    from dstenv.cli import main

    data = tmp_path / "d"
    assert main(["generate", "--frames", "4", "--grid", "16", "--cell-size", "1.0",
                 "--episode-length", "30", "--split", "train", "--quiet", "--out",
                 str(data)]) == 0

    def broken(*a, **k):
        raise ValueError("train: the loss is nan at epoch 1, batch 1")

    monkeypatch.setattr(train_module, "train", broken)
    assert main(["train", "--data", str(data), "--out", str(tmp_path / "m")]) == 2
    assert "the loss is nan" in capsys.readouterr().err
    assert not (tmp_path / "m").exists()
    (tmp_path / "kept").mkdir()  # a folder that was there stays
    assert main(["train", "--data", str(data), "--out", str(tmp_path / "kept")]) == 2
    assert (tmp_path / "kept").is_dir()
