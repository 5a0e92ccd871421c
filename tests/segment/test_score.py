"""The one orchestration: observed cells, object counts, ties, several episodes per map."""

import numpy as np
import pytest
import torch

from dstenv.dst import CLASSES, DSTParams
from dstenv.segment.replay import Episode, filter_episode
from dstenv.segment.score import (
    SCOPES,
    object_counts,
    observed_cells,
    past_grids,
    score,
    tie_cells,
)
from dstenv.segment.segmenters import DSTFreeSegmenter, DSTSegmenter, Segmenter

NAV, BUILD, STATIC, MOVING = (CLASSES.index(c) for c in ("navigable", "building", "static",
                                                          "moving"))


def _episode(poses, sensor, steps, labels=None, **kw):
    t, h, w = sensor.shape
    k = len(steps)
    labels = np.full((k, h, w), NAV, np.uint8) if labels is None else labels
    return Episode(0, sensor, np.full((t, h, w), 2, np.uint8), np.asarray(poses, float),
                   np.array(steps), labels, sensor[list(steps)] != 0, 1.0, **kw)


def test_observed_accumulates_sweeps_and_follows_the_ego():
    sensor = np.zeros((3, 6, 6), np.uint8)
    sensor[0, 2, 3] = 1  # seen at t=0 only
    sensor[1, 4, 4] = 2  # seen at t=1 only
    # the ego drives one cell (1 m) forward between t=1 and t=2: rows grow by one
    ep = _episode([[0, 0, 0], [0, 0, 0], [1, 0, 0]], sensor, [1, 2])
    obs = observed_cells(ep)
    assert obs[0].sum() == 2 and obs[0, 2, 3] and obs[0, 4, 4]
    assert obs[1].sum() == 2 and obs[1, 3, 3] and obs[1, 5, 4]
    assert ep.visible[1].sum() == 0  # nothing in the current sweep
    # without the filter history, observed = visible
    ep.history, ep.stored_x = False, np.zeros((2, 10, 6, 6), np.float32)
    np.testing.assert_array_equal(observed_cells(ep), ep.visible)


def test_observed_uses_only_fused_sweeps():
    sensor = np.zeros((3, 4, 4), np.uint8)
    sensor[1, 0, 0] = 1  # a sweep the 2-step filter never fuses
    sensor[2, 1, 1] = 1
    ep = _episode(np.zeros((3, 3)), sensor, [2], period=2)
    assert observed_cells(ep)[0].sum() == 1 and observed_cells(ep)[0, 1, 1]
    with pytest.raises(ValueError, match="multiples of the fusion period"):
        _episode(np.zeros((3, 3)), sensor, [1], period=2)


def test_filter_period_fuses_every_pth_step_with_previous_fused_as_t_minus_1():
    rng = np.random.default_rng(1)
    sensor = rng.integers(0, 3, (5, 6, 6), dtype=np.uint8)
    full = _episode(np.zeros((5, 3)), sensor, [0, 2, 4])
    sparse = _episode(np.zeros((3, 3)), sensor[[0, 2, 4]], [0, 1, 2])
    slow = _episode(np.zeros((5, 3)), sensor, [0, 2, 4], period=2)
    p = DSTParams.default()
    np.testing.assert_array_equal(filter_episode(slow, p), filter_episode(sparse, p))
    assert not np.array_equal(filter_episode(slow, p), filter_episode(full, p))


def test_object_counts_by_hand():
    labels = np.full((20, 20), NAV)
    labels[10:12, 10:12] = STATIC  # near the ego (cell 10, 10), recovered
    labels[1:3, 1:3] = STATIC  # about 12.7 cells away, predicted moving: missed
    labels[10:12, 17:19] = MOVING  # 7.5 cells away, recovered
    labels[18, 0] = STATIC  # never observed: not counted
    pred = labels.copy()
    pred[1:3, 1:3] = MOVING
    pred[18, 0] = NAV
    pred[0, 19] = STATIC  # a false static object
    observed = np.ones((20, 20), bool)
    observed[18, 0] = False
    c = object_counts(pred, labels, observed, cell_size=1.0)
    s, m = c[0], c[1]
    assert s[:, 0].sum() == 2 and s[0, :2].tolist() == [1, 1] and s[1, :2].tolist() == [1, 0]
    assert s[:, 2].sum() == 2 and s[:, 3].sum() == 1  # {near static ok, false one}
    assert m[0].tolist() == [1, 1, 1, 1]
    assert m[:, 2].sum() == 2 and m[:, 3].sum() == 1  # the missed static blob is a false moving


def test_tie_cells_counts_building_static_ties():
    betp = np.zeros((1, 5, 2, 2), np.float32)
    betp[0, NAV] = 1.0
    betp[0, :, 0, 0] = [0, 0, 0.4, 0.4, 0.2]  # tied maximum
    betp[0, :, 0, 1] = [0.5, 0, 0.25, 0.25, 0]  # tied, but not the maximum
    labels = np.zeros((1, 2, 2), np.uint8)
    labels[0, 1, 1] = 255
    assert tie_cells(betp, labels) == (1, 3)


class _Const(Segmenter):
    def __init__(self, label, cls):
        self.label, self.name, self.cls = label, label, cls

    def predict(self, x):
        return torch.full((x.shape[0], *x.shape[2:]), self.cls, dtype=torch.int64)


def test_score_keys_frames_by_seed_episode_step():
    rng = np.random.default_rng(0)
    sensor = rng.integers(0, 3, (4, 5, 5), dtype=np.uint8)
    a = _episode(np.zeros((4, 3)), sensor, [1, 3])
    b = _episode(np.zeros((4, 3)), sensor, [1, 3], episode=1)  # same map, other episode
    segs = [DSTSegmenter(DSTParams.default()), _Const("road", NAV)]
    res = score(segs, [a, b], DSTParams.default(), examples=[(0, 1, 3), (0, 0, 1)])
    assert res.drives == [(0, 0), (0, 1)] and res.clusters.tolist() == [0, 0]
    assert set(res.examples["road"]) == {(0, 1, 3), (0, 0, 1)}
    for sc in SCOPES:
        assert res.confusion["road"][sc].shape == (2, 5, 5)
    # labels are all navigable: the constant road segmenter is right on every counted cell
    assert res.confusion["road"]["all"][0, NAV, NAV] == 2 * 25
    with pytest.raises(ValueError, match="unique"):
        score([segs[1], segs[1]], [a], DSTParams.default())


def test_score_without_history_scores_only_generation_params():
    sensor = np.ones((2, 4, 4), np.uint8)
    ep = _episode(np.zeros((2, 3)), sensor, [0, 1], history=False,
                  stored_x=np.zeros((2, 10, 4, 4), np.float32))
    gen = DSTParams.default()
    res = score([DSTSegmenter(gen, label="g"), DSTSegmenter(DSTParams.paper(), label="p")],
                [ep], gen)
    assert "p" in res.unscored and "filter history" in res.unscored["p"]
    assert set(res.confusion) == {"g"} and res.observed_definition == "visible"


def test_past_grids_read_the_step_one_second_earlier():
    rng = np.random.default_rng(2)
    sensor = rng.integers(0, 3, size=(21, 6, 5)).astype(np.uint8)
    poses = np.zeros((21, 3))
    poses[:, 0] = np.arange(21) * 0.1  # 0.1 m a step: after 10 steps one cell forward
    past = past_grids(_episode(poses, sensor, [5, 12, 20]))
    assert not past[0].any()  # step 5 has no step -5
    np.testing.assert_array_equal(past[1][1:], sensor[2][:-1])  # moved one row nearer
    np.testing.assert_array_equal(past[2][1:], sensor[10][:-1])
    # stored frames: rows are the stored steps (stride 10 here)
    ep = _episode(poses[[0, 10, 20]], sensor[[0, 10, 20]], [0, 1, 2], history=False,
                  stored_x=np.zeros((3, 10, 6, 5), np.float32),
                  stored_steps=np.array([0, 10, 20]), row_steps=np.array([0, 10, 20]))
    past = past_grids(ep)
    assert not past[0].any()
    np.testing.assert_array_equal(past[2][1:], sensor[10][:-1])


def test_score_gives_dst_free_the_sensor_grids():
    # a drive of free road with one cell occupied at steps 0-2 and seen free at step 3
    sensor = np.ones((4, 5, 5), np.uint8)
    sensor[:3, 2, 2] = 2
    ep = _episode(np.zeros((4, 3)), sensor, [2, 3])
    gen = DSTParams.default()
    res = score([DSTSegmenter(gen), DSTFreeSegmenter(gen)], [ep], gen,
                examples=[(0, 0, 3)])
    assert res.examples["dst"][0, 0, 3][2, 2] != NAV  # the trail DST still holds
    assert res.examples["dst-free"][0, 0, 3][2, 2] == NAV
    assert (res.examples["dst-free"][0, 0, 3] == NAV).all()

