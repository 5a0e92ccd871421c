import numpy as np
import pytest
import torch

from dstenv.frame import IGNORE_INDEX
from dstenv.segment.losses import (
    LovaszSoftmaxLoss,
    WeightedCrossEntropyLoss,
    build_loss,
    class_statistics,
    lovasz_softmax,
    median_frequency_weights,
)
from dstenv.segment.losses.lovasz import lovasz_grad


def test_class_statistics_by_hand():
    a = np.array([[0, 0], [1, IGNORE_INDEX]])  # 3 labelled cells: two 0, one 1
    b = np.array([[0, 2], [2, 2]])  # 4 cells: one 0, three 2
    counts, present = class_statistics([a, b], 3)
    np.testing.assert_array_equal(counts, [3, 1, 3])
    np.testing.assert_array_equal(present, [7, 3, 4])


def test_median_frequency_weights_by_hand():
    # freq = [3/7, 1/3, 3/4]; median 3/7 -> w = [1, (3/7)/(1/3), (3/7)/(3/4)]
    w = median_frequency_weights(np.array([3, 1, 3]), np.array([7, 3, 4]))
    np.testing.assert_allclose(w, [1.0, 9 / 7, 4 / 7], rtol=1e-6)
    # plain frequencies: counts [80, 15, 5] -> freq .8 .15 .05, median .15
    np.testing.assert_allclose(
        median_frequency_weights(np.array([80, 15, 5])), [0.1875, 1.0, 3.0], rtol=1e-6
    )


def test_absent_class_gets_zero_weight():
    w = median_frequency_weights(np.array([10, 0, 30]))
    assert w[1] == 0 and w[0] == pytest.approx(2.0) and w[2] == pytest.approx(2 / 3)
    with pytest.raises(ValueError, match="no labelled cell"):
        median_frequency_weights(np.zeros(3))


def test_weighted_ce_is_paper_eq1():
    torch.manual_seed(0)
    logits = torch.randn(2, 3, 4, 5)
    target = torch.randint(0, 3, (2, 4, 5))
    target[0, 0, 0] = IGNORE_INDEX
    w = torch.tensor([0.5, 2.0, 1.0])
    loss = WeightedCrossEntropyLoss(w)(logits, target)
    logp = logits.log_softmax(1)
    keep = target != IGNORE_INDEX
    t = target.clamp(max=2)
    manual = -(w[t] * logp.gather(1, t[:, None])[:, 0])[keep].sum() / keep.sum()
    assert float(loss) == pytest.approx(float(manual), rel=1e-6)


def test_lovasz_perfect_prediction_is_zero():
    target = torch.tensor([[[0, 1], [2, IGNORE_INDEX]]])
    probs = torch.nn.functional.one_hot(target.clamp(max=2), 3).permute(0, 3, 1, 2).float()
    assert float(lovasz_softmax(probs, target)) == 0.0


def test_lovasz_grad_and_total_miss():
    # sorted gt [1, 0, 1]: J = 1 - I/U with I = [1, 1, 0], U = [2, 3, 3] -> [1/2, 2/3, 1]
    g = lovasz_grad(torch.tensor([1.0, 0.0, 1.0]))
    np.testing.assert_allclose(g.numpy(), [1 / 2, 2 / 3 - 1 / 2, 1 - 2 / 3], atol=1e-6)
    # all-wrong confident prediction: loss is 1 for each present class
    target = torch.tensor([[[0, 0], [1, 1]]])
    probs = torch.tensor([[[[0.0, 0.0], [1.0, 1.0]], [[1.0, 1.0], [0.0, 0.0]]]])
    assert float(lovasz_softmax(probs, target)) == pytest.approx(1.0)


def test_lovasz_has_gradient_and_ignores():
    logits = torch.randn(1, 3, 6, 6, requires_grad=True)
    target = torch.full((1, 6, 6), IGNORE_INDEX)
    assert float(LovaszSoftmaxLoss()(logits, target).detach()) == 0.0
    target[0, :3] = 1
    LovaszSoftmaxLoss()(logits, target).backward()
    assert logits.grad.abs().sum() > 0


def test_build_loss():
    with pytest.raises(ValueError, match="unknown loss"):
        build_loss("dice")
    with pytest.raises(ValueError, match="class weights"):
        build_loss("wce")
    loss = build_loss("wce+lovasz", np.ones(3, dtype=np.float32))
    logits = torch.randn(1, 3, 4, 4)
    target = torch.randint(0, 3, (1, 4, 4))
    expected = WeightedCrossEntropyLoss(np.ones(3))(logits, target) + LovaszSoftmaxLoss()(
        logits, target
    )
    assert float(loss(logits, target)) == pytest.approx(float(expected))
