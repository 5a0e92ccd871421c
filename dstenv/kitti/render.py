"""A PNG of one converted KITTI frame: points, sensor grid, DST moving channel, labels."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from dstenv.dst import CLASSES
from dstenv.frame import IGNORE_INDEX, Frame
from dstenv.grid import GridSpec
from dstenv.palette import CLASS_RGB, IGNORE_RGB, SENSOR_RGB, as_float, label_image
from dstenv.io import atomic_path
from dstenv.kitti.objects import Boxes

__all__ = ["render_frame"]

_LABEL_RGB = as_float(CLASS_RGB)
_IGNORE_RGB = as_float(IGNORE_RGB)
_SENSOR_RGB = as_float(SENSOR_RGB)


def _rgb_labels(labels: np.ndarray) -> np.ndarray:
    return as_float(label_image(labels, IGNORE_INDEX))


def render_frame(
    frame: Frame, boxes: Boxes, spec: GridSpec, path: str | Path, title: str = "",
    points: np.ndarray | None = None,
) -> Path:
    """Write a 4-panel PNG of one frame (forward up, left left, as :mod:`dstenv.grid`).

    Args:
        frame: a frame from :func:`dstenv.kitti.sequence.convert_sequence`.
        boxes: that frame's boxes (Velodyne frame), outlined on every panel.
        spec: the grid geometry.
        path: output ``.png`` (written to a temporary name, then renamed).
        title: figure title.
        points: optional ``(P, 3+)`` scan drawn in the first panel.

    Returns:
        The path written.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch

    x0, x1, y0, y1 = spec.extent
    c = spec.cell_size
    # imshow extent in (left, right, bottom, top) with horizontal = -y (left is left)
    ext = (-(y1 + c / 2), -(y0 - c / 2), x0 - c / 2, x1 + c / 2)
    fig, axes = plt.subplots(1, 4, figsize=(20, 5.6), constrained_layout=True)
    panels = [
        ("LIDAR points (height colour)", None),
        ("sensor grid: free / occupied / unknown", _SENSOR_RGB[frame.sensor]),
        ("DST BetP(moving)", frame.pignistic[CLASSES.index("moving")]),
        ("labels (near-white: ignore)", _rgb_labels(frame.labels)),
    ]
    corners = boxes.corners()
    for ax, (name, img) in zip(axes, panels, strict=True):
        ax.set_facecolor("white")
        if img is None:
            if points is not None:
                p = np.asarray(points)
                inside = (p[:, 0] > x0) & (p[:, 0] < x1) & (p[:, 1] > y0) & (p[:, 1] < y1)
                p = p[inside][::2]
                ax.scatter(-p[:, 1], p[:, 0], s=0.05, c=p[:, 2], cmap="viridis", vmin=-2, vmax=1)
        elif img.ndim == 2:
            im = ax.imshow(img, extent=ext, cmap="magma", vmin=0, vmax=1, interpolation="nearest")
            fig.colorbar(im, ax=ax, fraction=0.046)
        else:
            ax.imshow(img, extent=ext, interpolation="nearest")
        for k in range(len(boxes)):
            poly = np.vstack([corners[k], corners[k][:1]])
            ax.plot(-poly[:, 1], poly[:, 0], color="cyan" if img is not None and img.ndim == 2
                    else "magenta", lw=0.8)
        ax.plot(0, 0, marker="^", color="red", ms=6)
        # every panel shows exactly the grid: a far box must not stretch it
        ax.set_xlim(ext[0], ext[1])
        ax.set_ylim(ext[2], ext[3])
        ax.set_aspect("equal")
        ax.set_title(name, fontsize=10)
        ax.set_xlabel("to the right [m] (= -y)")
        ax.set_ylabel("x (forward) [m]")
    handles = [Patch(color=_LABEL_RGB[k], label=CLASSES[k]) for k in range(len(CLASSES))]
    handles.append(Patch(color=_IGNORE_RGB, label=f"ignore ({IGNORE_INDEX})"))
    axes[3].legend(handles=handles, loc="lower right", fontsize=7)
    if title:
        fig.suptitle(title, fontsize=11)
    path = Path(path)
    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=90, format="png")
    finally:
        plt.close(fig)
    return path
