"""Decision rules on a network's class scores (dstenv.segment.decide)."""

import numpy as np
import pytest
import torch

from dstenv.dst.frame import CLASSES
from dstenv.segment.checkpoint import load_segmenter, save_checkpoint
from dstenv.segment.decide import (OFFSETS, apply_decision, calibrate_offset, check_decision,
                                   decide_checkpoint, decide_ensemble, offset_confusion)
from dstenv.segment.segmenters import EnsembleSegmenter, TorchSegmenter

NAV, NON, BLD, STA, MOV = (CLASSES.index(c) for c in
                           ("navigable", "non_navigable", "building", "static", "moving"))


def _logits(rows):
    """(1, 5, 1, N) logits from N rows of 5 scores."""
    return torch.tensor(rows, dtype=torch.float32).T.reshape(1, 5, 1, len(rows))


def _x(n, free=()):
    """(1, 12, 1, n) input: BetP favouring navigable, seen-free channel at ``free``."""
    x = torch.zeros(1, 12, 1, n)
    x[0, NAV] = 0.6
    x[0, NON] = 0.4
    for j in free:
        x[0, 10, 0, j] = 1.0
    return x


def test_offset_moves_only_the_static_moving_boundary():
    # cells: static by 1, moving by 0.5, navigable (moving second), building
    lg = _logits([[0, 0, 0, 2, 1], [0, 0, 0, 1, 1.5], [3, 0, 0, 0, 2.9], [0, 0, 4, 1, 3]])
    x = _x(4)
    assert apply_decision(lg, x, None).tolist() == [[[STA, MOV, NAV, BLD]]]
    plain = {"moving_offset": 0.0, "free_veto": False}
    assert apply_decision(lg, x, plain).tolist() == [[[STA, MOV, NAV, BLD]]]
    # +1.25: the static cell (gap -1) turns moving; ground and building never change
    more = {"moving_offset": 1.25, "free_veto": False}
    assert apply_decision(lg, x, more).tolist() == [[[MOV, MOV, NAV, BLD]]]
    # -0.75: the moving cell (gap +0.5) turns static; exactly at the gap it stays static
    less = {"moving_offset": -0.75, "free_veto": False}
    assert apply_decision(lg, x, less).tolist() == [[[STA, STA, NAV, BLD]]]
    assert apply_decision(lg, x, {"moving_offset": -0.5, "free_veto": False})[0, 0, 1] == STA


def test_free_veto_clears_obstacles_seen_free():
    lg = _logits([[0, 0, 0, 2, 1], [0, 0, 0, 1, 1.5], [0, 0, 4, 1, 3]])
    x = _x(3, free=(1, 2))
    out = apply_decision(lg, x, {"moving_offset": 0.0, "free_veto": True})
    assert out.tolist() == [[[STA, NAV, NAV]]]  # BetP favours navigable over non_navigable


def test_check_decision_names_the_problem():
    ok = check_decision({"moving_offset": -1, "free_veto": True}, "fcn10+sensor", "f.pt")
    assert ok["moving_offset"] == -1.0 and isinstance(ok["moving_offset"], float)
    bad = [({"moving_offset": float("nan"), "free_veto": False}, "fcn10", "finite"),
           ({"moving_offset": True, "free_veto": False}, "fcn10", "finite"),
           ({"moving_offset": 0.0, "free_veto": 1}, "fcn10", "true or false"),
           ({"moving_offset": 0.0, "free_veto": True}, "fcn10", "current sweep"),
           ([0.0, True], "fcn10", "a dict")]
    for decision, inputs, words in bad:
        with pytest.raises(ValueError, match=words) as err:
            check_decision(decision, inputs, "f.pt")
        assert str(err.value).startswith("f.pt: ") and "\n" not in str(err.value)


class _Fixed:
    """A 'network' whose logits are the input's first five channels."""

    def logits(self, x):
        return x[:, :5]


def _sample(scores, labels, visible):
    x = torch.zeros(12, 1, len(scores))
    x[:5, 0] = torch.tensor(scores, dtype=torch.float32).T
    return {"x": x, "labels": torch.tensor([labels]), "visible": torch.tensor([visible])}


def test_offset_confusion_counts_rates_over_visible_object_cells():
    # static cells: gaps -2 (static), +1 (called moving), and one called building;
    # moving cells: gaps +3, -0.5 (called static); a hidden static cell called moving
    data = [_sample([[0, 0, 0, 2, 0], [0, 0, 0, 0, 1], [0, 0, 5, 0, 0], [0, 0, 0, 0, 3],
                     [0, 0, 0, 0.5, 0], [0, 0, 0, 0, 9]],
                    [STA, STA, STA, MOV, MOV, STA], [True] * 5 + [False])]
    conf = offset_confusion(_Fixed(), data, (0.0, -1.5, 2.5))
    # offset 0: 1/3 static called moving + 1/2 moving called static
    # -1.5: static gap +1 -> -0.5 (static): 0/3; moving +3 -> 1.5, -0.5 -> -2: 1/2
    # +2.5: static -2 -> 0.5 and +1 -> 3.5 moving: 2/3; moving both stay: 0/2
    np.testing.assert_allclose(conf, [1 / 3 + 1 / 2, 0 + 1 / 2, 2 / 3 + 0])
    off, all_ = calibrate_offset(_Fixed(), data, (0.0, -1.5, 2.5))
    assert off == -1.5 and len(all_) == 3
    with pytest.raises(ValueError, match="no visible moving cell"):
        offset_confusion(_Fixed(), [_sample([[0, 0, 0, 1, 0]], [STA], [True])])


def _net(tmp_path, seed, name="best.pt", inputs="fcn10+sensor", channels=12):
    """A random network's checkpoint, saved as dstenv train writes one."""
    torch.manual_seed(seed)
    seg = TorchSegmenter("unet-light", in_channels=channels, inputs=inputs)
    return save_checkpoint(tmp_path / name, {"spec": seg.spec(), "model": seg.model.state_dict(),
                                             "data": {"cell_size": 0.33}})


def _frames(n=3):
    """``n`` (12, 16, 16) samples with visible static and moving cells."""
    rng = torch.Generator().manual_seed(1)
    data = []
    for _ in range(n):
        x = torch.rand(12, 16, 16, generator=rng)
        x[10] = (x[10] > 0.7).float()
        y = torch.randint(0, 5, (16, 16), generator=rng)
        y[0, :4], y[1, :4] = STA, MOV  # both classes present
        data.append({"x": x, "labels": y, "visible": torch.ones(16, 16, dtype=torch.bool)})
    return data


def test_decide_checkpoint_round_trip(tmp_path):
    src = _net(tmp_path, 0)
    before = src.read_bytes()
    data = _frames()
    decision = decide_checkpoint(src, tmp_path / "decided.pt", data, "three frames")
    assert src.read_bytes() == before  # the plain checkpoint is left alone
    assert decision["moving_offset"] in OFFSETS and decision["free_veto"] is True
    assert decision["chosen_on"] == "three frames"
    assert len(decision["confusion"]["values"]) == len(OFFSETS)
    assert min(decision["confusion"]["values"]) == pytest.approx(
        decision["confusion"]["values"][OFFSETS.index(decision["moving_offset"])])
    decided = load_segmenter(tmp_path / "decided.pt")
    plain = load_segmenter(src)
    assert plain.decision is None and decided.decision["moving_offset"] == decision[
        "moving_offset"]
    x = torch.stack([d["x"] for d in data])
    assert torch.equal(decided.predict(x), apply_decision(plain.logits(x), x, decision))
    assert torch.equal(plain.predict(x), plain.logits(x).argmax(1))
    assert decided.describe()["decision"]["free_veto"] is True
    # a decision the network cannot apply is refused when loading, naming the file
    ckpt = torch.load(tmp_path / "decided.pt", weights_only=True)
    ckpt.pop("format"), ckpt.pop("version")
    save_checkpoint(tmp_path / "odd.pt", {**ckpt, "decision": {"moving_offset": "x",
                                                              "free_veto": True}})
    with pytest.raises(ValueError, match="odd.pt: decision.moving_offset"):
        load_segmenter(tmp_path / "odd.pt")


def test_ensemble_averages_logits_and_decides_on_them(tmp_path):
    srcs = [_net(tmp_path, k, f"seed{k}.pt") for k in range(3)]
    data = _frames()
    x = torch.stack([d["x"] for d in data])
    nets = [load_segmenter(p) for p in srcs]
    mean = torch.stack([n.logits(x) for n in nets]).mean(0)
    ens = EnsembleSegmenter(nets)
    assert torch.allclose(ens.logits(x), mean) and torch.equal(ens.predict(x), mean.argmax(1))
    decision = decide_ensemble(srcs, tmp_path / "ensemble.pt", data, "three frames")
    # the offset is the ensemble's own, chosen on its mean scores
    assert decision["moving_offset"] == calibrate_offset(ens, data)[0]
    loaded = load_segmenter(tmp_path / "ensemble.pt")
    assert isinstance(loaded, EnsembleSegmenter) and len(loaded.members) == 3
    assert loaded.trained_cell_size == 0.33 and loaded.inputs == "fcn10+sensor"
    assert torch.allclose(loaded.logits(x), mean)
    assert torch.equal(loaded.predict(x), apply_decision(mean, x, decision))
    assert loaded.describe()["decision"]["moving_offset"] == decision["moving_offset"]
    ckpt = torch.load(tmp_path / "ensemble.pt", weights_only=True)
    assert [m["source"] for m in ckpt["ensemble"]] == [str(p) for p in srcs]
    # loaded by --checkpoint, its label says how it decides; describe names its sources
    assert loaded.label == "unet-light ensemble of 3, calibrated + free"
    d = loaded.describe()
    assert [m["sha256"] for m in d["members"]] == [m["sha256"] for m in ckpt["ensemble"]]
    assert d["parameters"] == 3 * sum(p.numel() for p in nets[0].model.parameters())


def test_decide_ensemble_refuses_bad_members_and_writes_nothing(tmp_path):
    srcs = [_net(tmp_path, k, f"seed{k}.pt") for k in range(2)]
    data, out = _frames(), tmp_path / "ens.pt"
    before = srcs[1].read_bytes()

    def refused(members, match, dst=out, frames=data):
        with pytest.raises((ValueError, FileNotFoundError), match=match):
            decide_ensemble(members, dst, frames, "x")
        assert dst == srcs[1] or not dst.exists()

    # the destination is a member: refused before anything is written (it was overwritten)
    refused(srcs, r"seed1.pt: is one of the ensemble's members", dst=srcs[1])
    assert srcs[1].read_bytes() == before
    (tmp_path / "copy.pt").write_bytes(before)
    refused([srcs[0], srcs[0]], "the same network twice")
    refused([srcs[1], tmp_path / "copy.pt"], "the same network twice")  # same bytes
    refused(str(srcs[0]), "a list of two or more checkpoints")
    refused(srcs[:1], "a list of two or more checkpoints")
    refused([srcs[0], tmp_path / "nope.pt"], "checkpoint not found")
    _net(tmp_path, 5, "other.pt", inputs="fcn10", channels=10)
    refused([srcs[0], tmp_path / "other.pt"], r"ens.pt: ensemble members differ: .*other.pt")
    torch.manual_seed(6)
    odd = TorchSegmenter("unet-light", in_channels=12, inputs="fcn10+sensor")
    save_checkpoint(tmp_path / "coarse.pt", {"spec": odd.spec(), "model": odd.model.state_dict(),
                                             "data": {"cell_size": 0.5}})
    refused([srcs[0], tmp_path / "coarse.pt"], "trained on different cells")
    still = [{**f, "labels": torch.full((16, 16), STA)} for f in data]
    refused(srcs, "ens.pt: no visible moving cell .* in x; calibrate on drives with both",
            frames=still)
    decide_ensemble(srcs, out, data, "x")
    refused([srcs[0], out], "member .*ens.pt: an ensemble of 2 networks", dst=tmp_path / "n.pt")
    # the free-space rule needs the sweep: refused before calibrating on any frame
    _net(tmp_path, 7, "plain.pt", inputs="fcn10", channels=10)
    with pytest.raises(ValueError, match="free_veto needs the current sweep"):
        decide_ensemble([tmp_path / "other.pt", tmp_path / "plain.pt"], tmp_path / "p.pt",
                        [{"x": None}], "x")
    with pytest.raises(ValueError, match="at least two"):
        EnsembleSegmenter([load_segmenter(srcs[0])])


@pytest.mark.parametrize("value", [3, "a,b", {"a": 1}, [{"spec": {}}], [{}, "seed1.pt"], []])
def test_malformed_ensemble_entries_are_one_line_errors(tmp_path, value):
    from dstenv.segment.checkpoint import network_checkpoint

    ckpt = torch.load(_net(tmp_path, 0), weights_only=True)
    ckpt.pop("format"), ckpt.pop("version")
    save_checkpoint(tmp_path / "odd.pt", {**ckpt, "ensemble": value})
    for load in (load_segmenter, lambda p: network_checkpoint(p, "--init")):
        with pytest.raises(ValueError, match="odd.pt: 'ensemble' must list two or more"):
            load(tmp_path / "odd.pt")
    save_checkpoint(tmp_path / "nospec.pt", {"model": ckpt["model"]})
    with pytest.raises(ValueError, match="--init .*nospec.pt: checkpoint has no valid 'spec'"):
        network_checkpoint(tmp_path / "nospec.pt", "--init")
    # an ensemble file whose members name no source still says what to do
    save_checkpoint(tmp_path / "anon.pt", {"ensemble": [{"spec": ckpt["spec"],
                                                         "model": ckpt["model"]}] * 2})
    with pytest.raises(ValueError, match="use one of the networks it was made of"):
        network_checkpoint(tmp_path / "anon.pt", "--init")


def test_real_net_ensemble_row(tmp_path):
    """``real_net.ensemble``: one row for the seeds' ensemble, its offset chosen on its own
    scores; the reason instead when the validation drives cannot choose one."""
    from dstenv.segment.realnet import _ensemble

    ckpts = {f"unet-light kitti-labels (seed {k})": _net(tmp_path, k, f"seed{k}.pt")
             for k in range(2)}
    (tmp_path / "models").mkdir()
    said = []
    label = "unet-light kitti-labels ensemble of 2 seeds"
    facts = _ensemble(label, ckpts, tmp_path, _frames(), said.append)
    assert list(facts) == [label] and facts[label]["members"] == list(ckpts)
    assert facts[label]["checkpoint"] == str(tmp_path / "models" / "ensemble.pt")
    assert load_segmenter(facts[label]["checkpoint"]).decision["moving_offset"] == facts[
        label]["moving_offset"] and "offset" in said[0]
    still = [{**f, "labels": torch.full((16, 16), STA)} for f in _frames()]
    facts = _ensemble(label, ckpts, tmp_path, still, said.append)
    assert "no visible moving cell" in facts[label]["unchosen"]


def test_an_ensemble_loads_where_checkpoints_are_scored(tmp_path):
    """``dstenv benchmark --checkpoint`` / ``kitti evaluate`` load through
    ``load_checkpoints``: an ensemble of sensor-reading networks is checked against the
    data's 10 BetP channels like one network, and labelled apart from its members."""
    from dstenv.segment.evaluate import load_checkpoints

    srcs = [_net(tmp_path, k, f"seed{k}.pt") for k in range(2)]
    decide_ensemble(srcs, tmp_path / "ens.pt", _frames(), "three frames")
    one, ens = load_checkpoints([srcs[0], tmp_path / "ens.pt"], 10)
    assert isinstance(ens, EnsembleSegmenter) and ens.checkpoint == str(tmp_path / "ens.pt")
    assert one.label == "unet-light" and ens.label == "unet-light ensemble of 2, calibrated + free"
    with pytest.raises(ValueError, match="ens.pt: checkpoint takes 12 input channels"):
        load_checkpoints([tmp_path / "ens.pt"], 12)
