import numpy as np
import pytest
import torch

from dstenv.frame import IGNORE_INDEX
from dstenv.segment.metrics import (
    ConfusionMeter,
    accuracy,
    confusion_matrix,
    iou_per_class,
    mean_iou,
    precision_per_class,
    recall_per_class,
    summarize,
)

# 3 classes; rows true, columns predicted.
TRUE = np.array([[0, 0, 1, 1], [2, 2, 2, IGNORE_INDEX]])
PRED = np.array([[0, 1, 1, 1], [2, 0, 1, 0]])


def test_confusion_matrix_by_hand():
    cm = confusion_matrix(PRED, TRUE, 3)
    # true 0: pred 0,1 ; true 1: pred 1,1 ; true 2: pred 2,0,1 ; ignore skipped
    np.testing.assert_array_equal(cm, [[1, 1, 0], [0, 2, 0], [1, 1, 1]])


def test_confusion_matrix_mask_and_torch():
    mask = np.array([[True, True, False, False], [True, True, False, True]])
    cm = confusion_matrix(
        torch.as_tensor(PRED), torch.as_tensor(TRUE), 3, mask=torch.as_tensor(mask)
    )
    np.testing.assert_array_equal(cm, [[1, 1, 0], [0, 0, 0], [1, 0, 1]])


def test_metrics_by_hand():
    cm = np.array([[1, 1, 0], [0, 2, 0], [1, 1, 1]])
    # IoU: c0 1/(2+2-1)=1/3 ; c1 2/(2+4-2)=1/2 ; c2 1/(3+1-1)=1/3
    np.testing.assert_allclose(iou_per_class(cm), [1 / 3, 1 / 2, 1 / 3])
    assert mean_iou(cm) == pytest.approx((1 / 3 + 1 / 2 + 1 / 3) / 3)
    assert accuracy(cm) == pytest.approx(4 / 7)
    np.testing.assert_allclose(precision_per_class(cm), [1 / 2, 2 / 4, 1 / 1])
    np.testing.assert_allclose(recall_per_class(cm), [1 / 2, 2 / 2, 1 / 3])


def test_absent_class_is_nan_and_left_out_of_mean():
    cm = np.array([[3, 1, 0], [1, 3, 0], [0, 0, 0]])
    iou = iou_per_class(cm)
    assert np.isnan(iou[2])
    assert mean_iou(cm) == pytest.approx(0.6)
    s = summarize(cm, ("a", "b", "c"))
    assert s["iou"]["c"] is None and s["miou"] == pytest.approx(0.6) and s["cells"] == 8


def test_out_of_range_class_raises():
    with pytest.raises(ValueError, match="outside"):
        confusion_matrix(np.array([0, 7]), np.array([0, 1]), 3)
    with pytest.raises(ValueError, match="differ in size"):
        confusion_matrix(np.array([0, 1, 2]), np.array([0, 1]), 3)


def test_meter_accumulates_all_and_visible():
    meter = ConfusionMeter(3)
    vis = np.array([[True, True, False, False], [True, True, False, True]])
    for _ in range(2):
        meter.update(
            torch.as_tensor(PRED)[None], torch.as_tensor(TRUE)[None], torch.as_tensor(vis)[None]
        )
    np.testing.assert_array_equal(meter.all, 2 * np.array([[1, 1, 0], [0, 2, 0], [1, 1, 1]]))
    np.testing.assert_array_equal(meter.visible, 2 * np.array([[1, 1, 0], [0, 0, 0], [1, 0, 1]]))
    out = meter.summary(("a", "b", "c"))
    assert out["visible"]["cells"] == 8 and out["all"]["cells"] == 14
