"""``dstenv benchmark`` on converted KITTI shards with a checkpoint trained on simulated data."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from dstenv.cli import main
from dstenv.segment.checkpoint import save_checkpoint
from dstenv.segment.shardindex import split_index, stored_episodes
from dstenv.segment.segmenters import TorchSegmenter

from .conftest import make_sequence


@pytest.fixture(scope="module")
def sim_checkpoint(tmp_path_factory):
    """A tiny U-Net trained for one epoch on 8 simulated 32 x 32 frames."""
    from dstenv.data import ShardDataset
    from dstenv.data.generate import GenerateSpec, generate
    from dstenv.data.sampling import scenario_config
    from dstenv.segment.train import train

    tmp = tmp_path_factory.mktemp("sim")
    spec = GenerateSpec(
        config=scenario_config(None, {"grid": {"height": 32, "width": 32}}), frames=8, seed=0,
        scenario="default", split="train", frames_per_shard=8, episode_length=24, stride=4,
        warmup=4,
    )
    generate(spec, tmp / "data", progress=False)
    cfg = {"model": "unet-light", "model_kwargs": {"base": 4, "depth": 2}, "epochs": 1,
           "batch_size": 4, "device": "cpu"}
    train(cfg, ShardDataset(tmp / "data", split="train"), None, tmp / "m", progress=False,
          log=lambda m: None)
    return tmp / "m" / "last.pt"


@pytest.fixture(scope="module")
def kitti_root(tmp_path_factory):
    return make_sequence(tmp_path_factory.mktemp("kitti") / "root")


def _convert(root, out, *extra):
    assert main(["kitti", "convert", "--root", str(root), "--sequences", "0001", "--warmup", "0",
                 "--out", str(out), *extra]) == 0
    return out


def _bench(data, out, *extra):
    return main(["benchmark", "--data", str(data), "--out", str(out), "--quiet",
                 "--set", "eval_batch_size=2", *extra])


def test_every_frame_stored_scores_every_dst_variant(kitti_root, sim_checkpoint, tmp_path):
    ds = _convert(kitti_root, tmp_path / "ds", "--stride", "1")
    out = tmp_path / "b"
    assert _bench(ds, out, "--checkpoint", str(sim_checkpoint),
                  "--set", "tune.params={alpha=0.5}") == 0
    res = json.loads((out / "results.json").read_text())
    segs = res["segmenters"]
    assert list(segs) == ["dst (default)", "dst (paper)", "dst-free", "dst-tuned",
                          "unet-light"]
    assert [segs[k]["kind"] for k in segs] == ["dst", "dst", "dst", "dst", "learned"]
    assert segs["dst-tuned"]["describe"]["params"]["alpha"] == 0.5
    # each network also against the strongest non-learned row of each class
    strongest = res["real_goal"]["strongest"]
    assert "moving" in strongest
    for name in strongest:
        best = strongest[name]["baseline"]
        assert segs[best]["kind"] == "dst"
        assert strongest[name]["iou"] == max(
            v["visible"]["iou"][name] for v in segs.values()
            if v["kind"] == "dst" and v["visible"]["iou"][name] is not None)
        row = res["real_goal"]["networks"]["unet-light"][name]
        net, ref = segs["unet-light"]["visible"]["iou"][name], strongest[name]["iou"]
        assert abs(row["vs_strongest"]["diff"] - (net - ref)) < 1e-9
    assert "strongest non-learned row" in (out / "results.md").read_text()
    assert segs["unet-light"]["describe"]["checkpoint"] == str(sim_checkpoint)
    assert set(res["unscored"]) == {"dst-complete"}  # no train split, no complete.params
    assert res["data"]["source"] == "kitti" and res["data"]["test_frames"] == 6
    assert res["preset"] is None and res["real_goal"]["reference"] == "dst (default)"
    assert res["data"]["grid_shape"] == [256, 256] and res["histories"] == {}
    # every segmenter on exactly the same cells
    cells = {(v["all"]["cells"], v["visible"]["cells"]) for v in segs.values()}
    assert len(cells) == 1 and next(iter(cells))[1] > 0
    for name in ("results.md", "figures/confusion_all.png", "figures/confusion_visible.png",
                 "figures/examples.png"):
        assert (out / name).stat().st_size > 0, name
    md = (out / "results.md").read_text()
    assert "Evaluation-only data (kitti): 6 frames" in md and "--checkpoint" in md
    assert "preset" not in md.splitlines()[0] and "--preset" not in md


def test_refiltered_preset_matches_stored_preset(kitti_root, tmp_path):
    """Re-running `default` over the inputs of a `paper` conversion == converting with `default`."""
    a = _convert(kitti_root, tmp_path / "default", "--stride", "1")
    b = _convert(kitti_root, tmp_path / "paper", "--stride", "1", "--dst-preset", "paper")
    assert _bench(a, tmp_path / "ra") == 0 and _bench(b, tmp_path / "rb") == 0
    ra = json.loads((tmp_path / "ra" / "results.json").read_text())["segmenters"]
    rb_all = json.loads((tmp_path / "rb" / "results.json").read_text())
    rb = rb_all["segmenters"]
    # the paper conversion's own parameters
    assert rb_all["data"]["generation_dst_params"] == rb["dst (paper)"]["describe"]["params"]
    for label in ("dst (default)", "dst (paper)"):
        for scope in ("all", "visible"):
            ca = np.array(ra[label][scope]["confusion"])
            cb = np.array(rb[label][scope]["confusion"])
            # BetP stored as uint8 (within 1/510): argmax may flip only on near-ties
            assert np.abs(ca - cb).sum() <= 1e-3 * ca.sum(), (label, scope)
    assert rb["dst (default)"]["all"]["cells"] == ra["dst (default)"]["all"]["cells"] > 0


def test_sparse_frames_say_which_variants_are_not_scored(kitti_root, sim_checkpoint, tmp_path):
    ds = _convert(kitti_root, tmp_path / "ds", "--stride", "2")
    frames, config = split_index(sorted((ds / "test").glob("*.h5")))
    episodes, reason = stored_episodes(frames, config)
    assert episodes == [] and "stores steps 0, 2, 4" in reason and "every 1 step(s)" in reason
    out = tmp_path / "b"
    assert _bench(ds, out, "--checkpoint", str(sim_checkpoint)) == 0
    res = json.loads((out / "results.json").read_text())
    assert list(res["segmenters"]) == ["dst (default)", "dst-free", "unet-light"]
    assert set(res["unscored"]) == {"dst (paper)", "dst-tuned", "dst-complete"}
    assert "filter state between stored frames is lost" in res["unscored"]["dst (paper)"]
    assert "no train split to tune on" in res["unscored"]["dst-tuned"]
    md = (out / "results.md").read_text()
    assert "## Not scored" in md and "**dst (paper)**" in md


def test_bad_checkpoint_and_no_test_frames_are_one_line_errors(kitti_root, tmp_path, capsys):
    ds = _convert(kitti_root, tmp_path / "ds", "--stride", "2")
    seg = TorchSegmenter("unet-light", {"base": 4, "depth": 2}, in_channels=5)
    bad = save_checkpoint(tmp_path / "five.pt", {"spec": seg.spec(),
                                                 "model": seg.model.state_dict()})
    capsys.readouterr()
    assert _bench(ds, tmp_path / "b", "--checkpoint", str(bad)) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "takes 5 input channels but the data gives 10" in err
    assert main(["kitti", "evaluate", "--data", str(ds), "--checkpoint", str(bad)]) == 2
    assert "takes 5 input channels" in capsys.readouterr().err
    val = _convert(kitti_root, tmp_path / "val", "--stride", "2", "--split", "val")
    capsys.readouterr()
    assert _bench(val, tmp_path / "c") == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no test frames" in err


@pytest.mark.slow
def test_real_sample_smoke(real_root, sim_checkpoint, tmp_path):
    """The 40-frame real sample, every frame stored: a smoke test, not the paper's split."""
    ds = tmp_path / "ds"
    assert main(["kitti", "convert", "--root", str(real_root), "--sequences", "0003",
                 "--stride", "1", "--warmup", "0", "--out", str(ds)]) == 0
    assert _bench(ds, tmp_path / "b", "--checkpoint", str(sim_checkpoint)) == 0
    res = json.loads((tmp_path / "b" / "results.json").read_text())
    segs = res["segmenters"]
    assert list(segs) == ["dst (default)", "dst (paper)", "unet-light"]
    assert res["data"]["test_frames"] == 40
    assert set(res["unscored"]) == {"dst-tuned", "dst-complete"}
    assert len({v["all"]["cells"] for v in segs.values()}) == 1
    # real moving cars are found by the DST filter
    assert segs["dst (default)"]["all"]["iou"]["moving"] > 0.1


def test_dst_tuned_on_the_real_fine_tuning_frames_is_scored_only_after_them(kitti_root,
                                                                             tmp_path):
    """``dstenv benchmark --kitti --finetune-frames N``'s ``dst-tuned (real frames)``: DST
    parameters searched on frames 0 .. N-1 of the real drive, scored on the later ones."""
    from dstenv.data import ShardDataset
    from dstenv.dst import DSTParams
    from dstenv.segment.benchmark import run_benchmark
    from dstenv.segment.plan import split_drives, steps_before
    from dstenv.segment.real import REAL_TUNED, tune_on_real
    from dstenv.segment.tune import score_params, scope_masks

    ds = _convert(kitti_root, tmp_path / "ds", "--stride", "1")
    drives = split_drives(ShardDataset(ds, split="test", inputs="fcn10"), True, False,
                          lambda m: None)
    (ep,) = drives.episodes
    early = steps_before(ep, 3)
    assert early.steps.tolist() == [0, 1, 2] and len(early.labels) == 3
    assert steps_before(ep, 100) is ep and steps_before(ep, 0) is None

    seg = tune_on_real(ds, 3, {"budget": 4, "seed": 0, "scope": "observed"}, log=lambda m: None)
    trace = seg.info["tuning"]
    assert seg.label == REAL_TUNED and trace["frames"] == 3 and len(trace["evaluations"]) == 4
    assert seg.params == DSTParams.from_dict(trace["best_params"])
    # the search's figure is the tuned DST's mIoU on those three frames, recomputed
    assert trace["best_miou"] == pytest.approx(
        score_params([early], seg.params, masks=scope_masks([early], "observed")))
    assert trace["best_miou"] >= trace["start_miou"]
    with pytest.raises(ValueError, match="finetune_frames 0: no converted frame"):
        tune_on_real(ds, 0, {"budget": 2, "seed": 0, "scope": "observed"}, log=lambda m: None)

    cfg = {"score_from_step": 3, "models": [], "device": "cpu", "examples": 1,
           "eval_batch_size": 2, "tune": {"enabled": False}, "complete": {"enabled": False}}
    res = run_benchmark(cfg, tmp_path / "b", data_dir=ds, progress=False, log=lambda m: None,
                        dst_rows=[seg])
    row = res["segmenters"][REAL_TUNED]
    assert row["kind"] == "dst" and row["describe"]["params"] == seg.params.to_dict()
    assert row["describe"]["tuning"]["frames"] == 3
    assert res["data"]["test_frames"] == 3  # frames 3, 4, 5: none of the tuning frames


def test_fine_tuning_starts_from_the_network_that_reads_its_frames_best(kitti_root,
                                                                         sim_checkpoint,
                                                                         tmp_path):
    import torch

    from dstenv.data import ShardDataset
    from dstenv.segment.checkpoint import load_segmenter
    from dstenv.segment.metrics import confusion_matrix, mean_iou
    from dstenv.segment.real import start_scores

    ds = ShardDataset(_convert(kitti_root, tmp_path / "ds", "--stride", "1"), split="test",
                      inputs="fcn10")
    scores = start_scores({"a": sim_checkpoint, "b": sim_checkpoint}, ds, [0, 1, 2])
    seg = load_segmenter(sim_checkpoint, "cpu")
    samples = [ds[k] for k in (0, 1, 2)]
    pred = seg.predict(torch.stack([s["x"] for s in samples]))
    cm = confusion_matrix(pred, np.stack([s["labels"].numpy() for s in samples]), 5)
    assert scores == {"a": pytest.approx(mean_iou(cm)), "b": pytest.approx(mean_iou(cm))}
    assert 0.0 <= scores["a"] <= 1.0
    # an ensemble scores anywhere a checkpoint does, but is no start for a fine-tuning
    from dstenv.segment.checkpoint import load_checkpoint, save_checkpoint

    one = load_checkpoint(sim_checkpoint)
    member = {"spec": one["spec"], "model": one["model"], "source": str(sim_checkpoint)}
    save_checkpoint(tmp_path / "ens.pt", {"ensemble": [member, member]})
    assert set(start_scores({"a": sim_checkpoint, "e": tmp_path / "ens.pt"}, ds, [0])) == {"a"}


@pytest.mark.parametrize("inputs", ["fcn10+sensor", "fcn10+sensor+past"])
def test_real_net_is_trained_for_the_real_grid_and_scored_on_it(kitti_root, sim_checkpoint,
                                                                  tmp_path, inputs):
    """``real_net``: simulated drives at the converted grid, KITTI's labels, sensor input;
    scored on the real drive next to the simulated run's network, and a candidate start
    of the fine-tuning."""
    import torch

    from dstenv.data.manifest import load_manifest
    from dstenv.data.reader import ShardReader
    from dstenv.segment.checkpoint import load_checkpoint
    from dstenv.segment.presets import preset_config
    from dstenv.segment.real import real_benchmark

    # the past grid is the frame 10 steps earlier: a stride that stores it (tiny's 4 does not)
    cfg = preset_config("tiny", {"real_net": {"frames": 10, "epochs": 1, "inputs": inputs},
                                 **({"data": {"stride": 5}} if "past" in inputs else {})})
    sim = {"config": cfg, "segmenters": {
        "unet-light": {"kind": "learned", "describe": {"checkpoint": str(sim_checkpoint)}}}}
    res = real_benchmark(sim, tmp_path, str(kitti_root), ["0001"], finetune_frames=2,
                         finetune_epochs=(2, 1), gap=1, log=lambda m: None)
    facts = res["real"]["real_net"]
    # the fine-tuning's length: chosen on frame 2, between the fine-tuning and scored frames
    ep = res["real"]["finetune_start"]["epochs"]
    assert ep["candidates"] == [1, 2] and set(ep["miou"]) == {1, 2}
    assert ep["chosen_on"] == "frames 2-2" and ep["chosen"] == max(
        (1, 2), key=lambda e: (ep["miou"][e], -e))
    tuned_path = res["segmenters"]["fine-tuned on 2 real frames/sequence"]["describe"][
        "checkpoint"]
    assert tuned_path.endswith(f"epochs-{ep['chosen']}.pt")
    label = "unet-light kitti-labels"
    grid = load_manifest(tmp_path / "kitti" / "data")["grid_shape"]
    assert facts["grid"] == grid and facts["labels"] == "kitti"
    rdata = tmp_path / "kitti" / "real_net" / "data"
    assert load_manifest(rdata)["grid_shape"] == grid
    # converted without --osm: every simulated drive without a map too (real_net.map
    # "match"), though the tiny preset's own drives have one
    assert cfg["data"]["overrides"].get("gis", {}).get("source", "map") == "map"
    assert facts["no_map"] is True
    # agents labelled moving by the real labels' rule (real_net.moving "match"): KITTI's
    # 10 cm a 0.1 s frame = 1 m/s, not the simulator's 0.1 m/s
    assert facts["moving_threshold"] == pytest.approx(1.0)
    # real_net.decide: the tiny drives' val split has no visible moving cell to choose
    # an offset on: no decided row, and the reason recorded
    assert set(facts["decided"]) == {label} and "no visible moving cell" in facts[
        "decided"][label]["unchosen"]
    assert not any("calibrated + free" in k for k in res["segmenters"])
    for shard in sorted(rdata.rglob("*.h5")):
        with ShardReader(shard) as r:
            assert r.attrs["config"]["labels"]["moving_threshold"] == pytest.approx(1.0)
            assert r.attrs["config"]["protocol"]["moving_rule"] == "speed"
            assert r.attrs["config"]["gis"]["source"] == "none"
            assert not r.get(0, ["gis"])["gis"].any()  # vacuous GIS grid: all 0
    ckpt = load_checkpoint(facts["checkpoints"][label])
    assert ckpt["spec"]["inputs"] == inputs and facts["inputs"] == inputs
    assert ckpt["spec"]["in_channels"] == {"fcn10+sensor": 12, "fcn10+sensor+past": 14}[inputs]
    assert ckpt["config"]["labels"] == "kitti"
    rows = res["segmenters"]
    assert {f"{label} (sim only)", "unet-light (sim only)"} <= set(rows)
    assert rows[f"{label} (sim only)"]["describe"]["inputs"] == inputs
    # both networks were candidates for the fine-tuning start
    assert set(res["real"]["finetune_start"]["start_miou"]) == {"unet-light", label}
    tuned = torch.load(tmp_path / "kitti" / "finetune" / "last.pt", weights_only=True)
    assert tuned["spec"]["inputs"] == res["segmenters"][
        "fine-tuned on 2 real frames/sequence"]["describe"]["inputs"]
    assert set(res["real_goal"]["networks"]) >= {f"{label} (sim only)"}
    # trained on real frames: held to the goal's larger margin
    goal_rows = res["real_goal"]["networks"]
    assert goal_rows["fine-tuned on 2 real frames/sequence"]["margin"] == 0.15
    assert goal_rows[f"{label} (sim only)"]["margin"] == 0.10
    # a network reading the sensor (and past) grids as the start, several lengths
    from dstenv.segment.real import _finetune

    path, info = _finetune({label: Path(facts["checkpoints"][label])}, tmp_path / "kitti" / "data",
                           2, [1, 2], 1, tmp_path / "ft2", False, lambda m: None)
    assert info["start"] == label and path.name == f"epochs-{info['epochs']['chosen']}.pt"
    assert torch.load(path, weights_only=True)["spec"]["inputs"] == inputs
    # a rerun keeps each length's own weights and choice; a longer run without the
    # snapshots is refused instead of being taken for a shorter one
    again, info2 = _finetune({label: Path(facts["checkpoints"][label])},
                             tmp_path / "kitti" / "data", 2, [1, 2], 1, tmp_path / "ft2", False,
                             lambda m: None)
    assert info2["epochs"] == info["epochs"] and again == path
    (tmp_path / "ft2" / "epochs-1.pt").unlink()
    with pytest.raises(ValueError, match="holds a fine-tuning of 2 epochs but no epochs-1.pt"):
        _finetune({label: Path(facts["checkpoints"][label])}, tmp_path / "kitti" / "data", 2,
                  [1, 2], 1, tmp_path / "ft2", False, lambda m: None)


def test_several_fine_tuning_lengths_need_frames_to_choose_on(kitti_root, sim_checkpoint,
                                                              tmp_path):
    from dstenv.segment.real import _finetune

    ds = _convert(kitti_root, tmp_path / "ds", "--stride", "1")
    with pytest.raises(ValueError, match="a gap > 0 holding frames"):
        _finetune({"a": sim_checkpoint}, ds, 2, [1, 2], 0, tmp_path / "ft", False,
                  lambda m: None)
    with pytest.raises(ValueError, match="lengths must be >= 1"):
        _finetune({"a": sim_checkpoint}, ds, 2, [0], 1, tmp_path / "ft", False, lambda m: None)
