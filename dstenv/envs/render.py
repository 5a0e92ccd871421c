"""Top-view rendering: the perception grid beside the ground truth.

Left panel: the perception grid, each cell coloured by the BetP-weighted mix of the
class colours and darkened by its ignorance (uniform BetP, i.e. never observed, is
near black). Right panel: the exact labels, with cells the LIDAR did not see this
sweep dimmed, and the LIDAR returns as white dots. The ego is the white box at the
centre, heading up (forward is up, left is left: the axes of :mod:`dstenv.grid`).

Only numpy and Pillow (a matplotlib dependency) are used for ``rgb_array``;
``human`` opens a pygame window on first use, so importing this module never needs
a display.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from dstenv.dst import CLASSES
from dstenv.frame import IGNORE_INDEX, Frame
from dstenv.grid import GridSpec
from dstenv.palette import CLASS_RGB

__all__ = ["CLASS_COLORS", "render_frame", "HumanWindow"]

#: ``(5, 3) uint8`` RGB colour of each class in ``CLASSES`` order (:mod:`dstenv.palette`).
CLASS_COLORS: np.ndarray = CLASS_RGB
_BG = np.array([24, 24, 28], np.uint8)
_PANEL_PX = 448  # target panel edge [px]
_EGO_LENGTH, _EGO_WIDTH = 4.5, 1.9  # [m] footprint drawn for the ego


def _perception_rgb(betp: np.ndarray) -> np.ndarray:
    """``(5, H, W)`` BetP -> ``(H, W, 3) uint8``: colour mix, dark where ignorant."""
    mix = np.tensordot(betp.astype(np.float32), CLASS_COLORS.astype(np.float32), axes=(0, 0))
    n = betp.shape[0]
    conf = np.clip((betp.max(axis=0) - 1.0 / n) / (1.0 - 1.0 / n), 0.0, 1.0)
    shade = 0.2 + 0.8 * conf
    return np.clip(mix * shade[..., None], 0, 255).astype(np.uint8)


def _truth_rgb(labels: np.ndarray, visible: np.ndarray) -> np.ndarray:
    """``(H, W)`` labels -> ``(H, W, 3) uint8``; unseen cells at 45% brightness."""
    lab = np.where(labels == IGNORE_INDEX, 0, labels)
    rgb = CLASS_COLORS[lab].astype(np.float32)
    rgb[~visible] *= 0.45
    rgb[labels == IGNORE_INDEX] = 0
    return rgb.astype(np.uint8)


def _upscale(img: np.ndarray, k: int) -> np.ndarray:
    return np.repeat(np.repeat(img, k, axis=0), k, axis=1)


def _draw_ego(img: np.ndarray, spec: GridSpec, k: int) -> None:
    i0, j0 = spec.ego_cell
    ci, cj = (i0 + 0.5) * k, (j0 + 0.5) * k
    hl = max(_EGO_LENGTH / 2 / spec.cell_size * k, 3)
    hw = max(_EGO_WIDTH / 2 / spec.cell_size * k, 2)
    r0, r1 = int(ci - hl), int(ci + hl)
    c0, c1 = int(cj - hw), int(cj + hw)
    img[r0:r1, c0:c1] = 255
    img[r0:r0 + max(1, (r1 - r0) // 4), c0:c1] = (40, 200, 255)  # the front


def _draw_points(img: np.ndarray, points: np.ndarray, spec: GridSpec, k: int) -> None:
    pts = points[np.isfinite(points).all(axis=1)]
    i, j = spec.to_cell(pts[:, 0], pts[:, 1])
    ok = spec.inside(i, j)
    r = (i[ok] * k + k // 2).clip(0, img.shape[0] - 1)
    c = (j[ok] * k + k // 2).clip(0, img.shape[1] - 1)
    img[r, c] = 255


def render_frame(frame: Frame, spec: GridSpec, lidar_points: np.ndarray | None = None,
                 text: str = "") -> np.ndarray:
    """One RGB image of a frame.

    Args:
        frame: the frame (its ``pignistic``, ``labels`` and ``visible`` are drawn).
        spec: its grid geometry.
        lidar_points: optional ``(B, 2)`` ego-frame returns [m] (NaN rows skipped).
        text: a status line (time, speed, reward...) printed under the panels.

    Returns:
        ``(Hi, Wi, 3) uint8`` image.
    """
    from PIL import Image, ImageDraw, ImageFont

    k = max(1, int(round(_PANEL_PX / max(spec.shape))))
    left = _upscale(_perception_rgb(frame.pignistic), k)
    right = _upscale(_truth_rgb(frame.labels, frame.visible), k)
    if lidar_points is not None:
        _draw_points(right, lidar_points, spec, k)
    for panel in (left, right):
        _draw_ego(panel, spec, k)
    h, w = left.shape[:2]
    pad, top, bottom = 8, 22, 44
    img = np.empty((top + h + bottom, 3 * pad + 2 * w, 3), np.uint8)
    img[:] = _BG
    img[top:top + h, pad:pad + w] = left
    img[top:top + h, 2 * pad + w:2 * pad + 2 * w] = right
    pil = Image.fromarray(img)
    draw = ImageDraw.Draw(pil)
    # Pillow's scalable default font: its tiny bitmap font runs words together
    draw.font = ImageFont.load_default(size=13)
    draw.text((pad, 4), "perception grid: BetP, dark where unknown", fill=(235, 235, 235))
    draw.text((2 * pad + w, 4), "ground truth: dim where the sensor sees nothing now",
              fill=(235, 235, 235))
    x, y = pad, top + h + 6
    for name, col in zip(CLASSES, CLASS_COLORS):
        draw.rectangle([x, y + 2, x + 10, y + 12], fill=tuple(int(c) for c in col))
        draw.text((x + 14, y), name, fill=(235, 235, 235))
        x += 14 + int(draw.textlength(name)) + 16
    draw.text((pad, y + 18), text, fill=(200, 200, 200))
    return np.asarray(pil)


class HumanWindow:
    """A pygame window showing rendered frames (opened lazily, closed by :meth:`close`)."""

    def __init__(self, title: str = "dstenv") -> None:
        self.title = title
        self._screen: Any = None

    def show(self, img: np.ndarray) -> None:
        """Display an ``(Hi, Wi, 3) uint8`` image, opening the window if needed."""
        import pygame

        if self._screen is None:
            # the display alone: pygame.init() would also open the audio mixer, which
            # prints ALSA errors on headless machines
            pygame.display.init()
            pygame.display.set_caption(self.title)
            self._screen = pygame.display.set_mode((img.shape[1], img.shape[0]))
        pygame.event.pump()
        surf = pygame.surfarray.make_surface(np.ascontiguousarray(img.transpose(1, 0, 2)))
        self._screen.blit(surf, (0, 0))
        pygame.display.flip()

    def close(self) -> None:
        """Close the window (no-op when it was never opened)."""
        if self._screen is not None:
            import pygame

            pygame.display.quit()
            self._screen = None
