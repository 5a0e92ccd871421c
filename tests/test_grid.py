"""The ego-grid axis convention of dstenv.grid."""

import numpy as np
import pytest

from dstenv.grid import GridSpec


def test_paper_default():
    spec = GridSpec()
    assert spec.shape == (256, 256) and spec.ego_cell == (128, 128)
    x_min, x_max, y_min, y_max = spec.extent
    assert x_max - x_min == pytest.approx(256 * 0.33)
    assert x_max == pytest.approx(128.5 * 0.33) and y_min == pytest.approx(-127.5 * 0.33)


def test_forward_is_up_and_left_is_left():
    spec = GridSpec(8, 6, 1.0)
    x, y = spec.cell_centers()
    assert x[spec.ego_cell] == 0 and y[spec.ego_cell] == 0
    assert x[0, 3] == 4.0 and x[7, 3] == -3.0  # row 0 is the far front
    assert y[4, 0] == 3.0 and y[4, 5] == -2.0  # column 0 is the far left
    i, j = spec.to_cell(np.array([4.0, 0.49, -0.51]), np.array([0.0, 0.0, 2.6]))
    assert i.tolist() == [0, 4, 5] and j.tolist() == [3, 3, 0]
    assert spec.inside(np.array([-1, 0, 7]), np.array([0, 6, 5])).tolist() == [False, False, True]


def test_cell_centres_roundtrip():
    spec = GridSpec(10, 12, 0.33)
    x, y = spec.cell_centers()
    i, j = spec.to_cell(x, y)
    assert np.array_equal(i, np.arange(10)[:, None].repeat(12, 1))
    assert np.array_equal(j, np.arange(12)[None, :].repeat(10, 0))


def test_rejects_bad_spec():
    with pytest.raises(ValueError, match="cell_size"):
        GridSpec(4, 4, 0.0)


def test_camera_mask_is_the_forward_wedge():
    from dstenv.grid import camera_mask

    spec = GridSpec(7, 7, 1.0)  # ego at (3, 3); row 0 is 3 m ahead
    got = camera_mask(spec, 90.0)
    want = np.zeros((7, 7), bool)
    for i in range(3):  # x = 3 - i ahead; |y| <= x within 45 deg
        x = 3 - i
        want[i, 3 - x:3 + x + 1] = True
    np.testing.assert_array_equal(got, want)
    narrow = camera_mask(spec, 30.0)  # only the straight-ahead column at 15 deg
    assert narrow.sum() == 3 and narrow[:3, 3].all()
    assert not camera_mask(spec, 179.0)[3:].any()  # nothing level with or behind the ego
    for bad in (0.0, 400.0, float("nan")):  # were 4 cells, the 360 mask, none
        with pytest.raises(ValueError, match="fov_deg must lie in"):
            camera_mask(spec, bad)
