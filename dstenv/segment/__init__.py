"""Segmenters on DST perception grids: the pure-DST baseline, FCN-DST and better.

Layout (after segmentation_models_pytorch):

* :mod:`~dstenv.segment.registry` -- ``create_segmenter(name, **kw)`` over
  :data:`SEGMENTERS` (``dst``, ``dst-tuned``, ``unet-light``, ``unet-temporal``,
  ``fcn8s-vgg16``);
* :mod:`~dstenv.segment.models` -- networks as encoder + decoder + head;
* :mod:`~dstenv.segment.losses` -- median-frequency weighted CE, Lovasz-softmax;
* :mod:`~dstenv.segment.metrics` -- confusion matrix, IoU, accuracy, precision, recall;
* :mod:`~dstenv.segment.replay` / :mod:`~dstenv.segment.tune` -- re-running and
  tuning the DST filter on recorded drives;
* :mod:`~dstenv.segment.train`, :mod:`~dstenv.segment.checkpoint` -- ``dstenv train``;
* :mod:`~dstenv.segment.benchmark`, :mod:`~dstenv.segment.report` -- ``dstenv benchmark``.
"""

from __future__ import annotations

from dstenv.segment.checkpoint import load_checkpoint, load_segmenter, save_checkpoint
from dstenv.segment.metrics import ConfusionMeter, confusion_matrix, iou_per_class, mean_iou
from dstenv.segment.registry import SEGMENTERS, create_segmenter, register_segmenter
from dstenv.segment.segmenters import DSTSegmenter, Segmenter, TorchSegmenter

__all__ = [
    "SEGMENTERS",
    "create_segmenter",
    "register_segmenter",
    "Segmenter",
    "DSTSegmenter",
    "TorchSegmenter",
    "save_checkpoint",
    "load_checkpoint",
    "load_segmenter",
    "ConfusionMeter",
    "confusion_matrix",
    "iou_per_class",
    "mean_iou",
]
