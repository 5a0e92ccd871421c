"""dst-complete: a car-sized box behind the visible face, along the kerb."""

import numpy as np
import pytest
import torch

from dstenv.dst import CLASSES, DSTParams
from dstenv.segment.complete import DSTCompleteSegmenter, complete_frame, tune_completion

NAV, NON, BUILD, STATIC = (CLASSES.index(c) for c in ("navigable", "non_navigable", "building",
                                                       "static"))


def _street(h=40, w=40):
    """A road along the rows (columns 10..29), the ego at (20, 20); a kerb strip west."""
    betp = np.zeros((5, h, w), np.float32)
    betp[NON] = 0.6
    betp[NAV, :, 10:30] = 0.9
    betp[NON, :, 10:30] = 0.0
    betp[BUILD, :, :5] = 0.9  # buildings far west
    # the visible face of a parked car: column 12 (the side facing the ego), rows 18..22
    betp[:, 18:23, 12] = 0
    betp[STATIC, 18:23, 12] = 0.9
    return betp


def test_box_grows_away_from_the_ego_along_the_kerb():
    betp = _street()
    plain = complete_frame(betp, 1.0, length_m=0)
    np.testing.assert_array_equal(plain, betp.argmax(0))
    pred = complete_frame(betp, 1.0, length_m=9.0, width_m=3.0, min_cells=3)
    filled = pred == STATIC
    rows, cols = np.nonzero(filled)
    # 9 m along the road (rows), about 3 m across it, on the far side (columns <= 12)
    assert rows.max() - rows.min() + 1 in (9, 10) and cols.max() <= 12
    assert 3 <= cols.max() - cols.min() + 1 <= 4
    assert not (filled & (betp.argmax(0) == BUILD)).any()
    # cells seen free (free BetP above max_free) are kept
    kept = complete_frame(betp, 1.0, length_m=9.0, width_m=3.0, min_cells=3, max_free=0.5)
    assert (kept == STATIC).sum() < filled.sum()


def test_small_components_are_left_alone_and_segmenter_batches():
    betp = _street()
    assert (complete_frame(betp, 1.0, 9.0, 3.0, min_cells=6) == betp.argmax(0)).all()
    seg = DSTCompleteSegmenter(DSTParams.default(), 1.0,
                               {"length_m": 9.0, "width_m": 3.0, "min_cells": 3})
    out = seg.predict(torch.from_numpy(np.stack([betp, betp])))
    assert out.shape == (2, 40, 40) and out.dtype == torch.int64
    assert seg.describe()["completion"]["length_m"] == 9.0
    with pytest.raises(ValueError, match="BetP input"):
        seg.predict(torch.zeros(2, 3, 4, 4))


def test_tune_completion_finds_the_car_size():
    from dstenv.segment.replay import Episode

    # sensor: the car's near face occupied, the rest of the road free, map road / sidewalk
    h = w = 30
    sensor = np.ones((2, h, w), np.uint8)
    sensor[:, 13:17, 10] = 2
    sensor[:, :, :10] = 0  # behind the face: never seen
    gis = np.full((2, h, w), 3, np.uint8)
    gis[:, :, 6:25] = 2
    labels = np.full((1, h, w), NAV, np.uint8)
    labels[0, :, :6] = NON
    labels[0, 12:18, 7:11] = STATIC  # the whole car body
    ep = Episode(0, sensor, gis, np.zeros((2, 3)), np.array([1]), labels, sensor[[1]] != 0, 0.5)
    grid = {"length_m": (0.0, 3.0), "width_m": (2.0,), "min_cells": (2,), "max_free": (1.01,)}
    best, trace = tune_completion([ep], DSTParams.default(), "all", grid)
    assert best["length_m"] == 3.0 and len(trace["evaluations"]) == 2
    assert trace["evaluations"][1]["miou"] > trace["evaluations"][0]["miou"]


def test_registry_builds_dst_complete():
    from dstenv.segment.registry import create_segmenter

    seg = create_segmenter("dst-complete", params={"alpha": 0.2}, cell_size=1.0,
                           completion={"length_m": 9.0, "width_m": 3.0, "min_cells": 3})
    assert seg.label == "dst-complete" and seg.params.alpha == 0.2
    betp = _street()
    np.testing.assert_array_equal(seg.predict(torch.from_numpy(betp[None]))[0].numpy(),
                                  complete_frame(betp, 1.0, 9.0, 3.0, 3))
