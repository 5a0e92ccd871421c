"""Rendering: panel layout and colours."""

from __future__ import annotations

import numpy as np

from dstenv.envs.render import CLASS_COLORS, render_frame
from dstenv.frame import Frame
from dstenv.grid import GridSpec


def test_render_panels_show_certain_cells_in_class_colours():
    spec = GridSpec(32, 32, 1.0)
    betp = np.zeros((5, 32, 32), np.float32)
    betp[0] = 1.0  # certain navigable everywhere ...
    betp[:, :4, :4] = 0.2  # ... but the far-left corner is unknown
    labels = np.full((32, 32), 4, np.uint8)  # moving everywhere
    visible = np.ones((32, 32), bool)
    visible[:, 16:] = False
    f = Frame(betp, betp, labels, visible, np.zeros((32, 32), np.uint8),
              np.zeros((32, 32), np.uint8), np.zeros(3))
    img = render_frame(f, spec, text="t=0")
    assert img.dtype == np.uint8 and img.ndim == 3 and img.shape[2] == 3
    k = 14  # 448 px / 32 cells
    top, pad = 22, 8
    left = img[top:top + 32 * k, pad:pad + 32 * k]
    right = img[top:top + 32 * k, 2 * pad + 32 * k:2 * pad + 64 * k]
    assert np.array_equal(left[100, 300], CLASS_COLORS[0])  # certain navigable
    assert left[k, k].max() < CLASS_COLORS[0].max() * 0.3  # unknown is dark
    assert np.array_equal(right[100, 100], CLASS_COLORS[4])  # seen moving
    assert np.array_equal(right[100, 400], (CLASS_COLORS[4] * 0.45).astype(np.uint8))
    assert (left[16 * k, 16 * k] == 255).all()  # the ego box
