"""Decision rules on a network's class scores (dstenv.segment.decide)."""

import numpy as np
import pytest
import torch

from dstenv.dst.frame import CLASSES
from dstenv.segment.checkpoint import load_segmenter, save_checkpoint
from dstenv.segment.decide import (OFFSETS, apply_decision, calibrate_offset, check_decision,
                                   decide_checkpoint, offset_confusion)
from dstenv.segment.segmenters import TorchSegmenter

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


def test_decide_checkpoint_round_trip(tmp_path):
    torch.manual_seed(0)
    seg = TorchSegmenter("unet-light", in_channels=12, inputs="fcn10+sensor")
    src = save_checkpoint(tmp_path / "best.pt", {"spec": seg.spec(),
                                                "model": seg.model.state_dict()})
    before = src.read_bytes()
    rng = torch.Generator().manual_seed(1)
    data = []
    for _ in range(3):
        x = torch.rand(12, 16, 16, generator=rng)
        x[10] = (x[10] > 0.7).float()
        y = torch.randint(0, 5, (16, 16), generator=rng)
        y[0, :4], y[1, :4] = STA, MOV  # both classes present
        data.append({"x": x, "labels": y, "visible": torch.ones(16, 16, dtype=torch.bool)})
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
