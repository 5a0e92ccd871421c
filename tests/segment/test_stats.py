"""Cluster bootstrap over maps."""

import numpy as np
import pytest

from dstenv.segment.stats import (
    confusion_summary,
    diff_ci,
    iou_batch,
    miou_batch,
    percentile_ci,
    resample_weights,
)


def test_resample_weights_draw_whole_maps():
    w = resample_weights(np.array([7, 7, 9, 11]), n=500, seed=1)
    assert w.shape == (500, 4)
    np.testing.assert_array_equal(w[:, 0], w[:, 1])  # two episodes of map 7 travel together
    # each resample draws 3 maps: the weights of the distinct maps sum to 3
    np.testing.assert_array_equal(w[:, 0] + w[:, 2] + w[:, 3], 3)
    np.testing.assert_array_equal(w, resample_weights(np.array([7, 7, 9, 11]), n=500, seed=1))


def test_iou_and_miou_batch_match_by_hand():
    cm = np.array([[[1, 1, 0], [0, 2, 0], [0, 0, 0]]])
    np.testing.assert_allclose(iou_batch(cm)[0, :2], [1 / 2, 2 / 3])
    assert np.isnan(iou_batch(cm)[0, 2])  # absent from the labels
    assert miou_batch(cm)[0] == pytest.approx((1 / 2 + 2 / 3) / 2)


def test_interval_covers_the_spread_of_drives():
    good = np.diag([10, 10]).astype(np.int64)
    bad = np.array([[5, 5], [5, 5]])
    per_drive = np.stack([good, bad, good, bad])
    w = resample_weights(np.arange(4), n=2000, seed=0)
    s = confusion_summary(per_drive, w, ("a", "b"))
    lo, hi = s["ci"]["miou"]
    assert lo < s["miou"] < hi and lo >= 1 / 3 - 1e-9 and hi <= 1.0
    d, ci = diff_ci(per_drive, per_drive, w, miou_batch)
    assert d == 0.0 and ci == [0.0, 0.0]  # paired: identical segmenters never differ
    assert percentile_ci(np.array([np.nan])) is None
