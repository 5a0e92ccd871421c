"""Segmenters on DST perception grids: the pure-DST baseline, FCN-DST and better.

Layout (after segmentation_models_pytorch):

* :mod:`~dstenv.segment.registry` -- ``create_segmenter(name, **kw)`` over
  :data:`SEGMENTERS` (``dst``, ``dst-tuned``, ``unet-light``, ``unet-temporal``,
  ``fcn8s-vgg16``; ``dst-complete`` is built by the benchmark);
* :mod:`~dstenv.segment.models` -- networks as encoder + decoder + head;
* :mod:`~dstenv.segment.losses` -- median-frequency weighted CE, Lovasz-softmax;
* :mod:`~dstenv.segment.metrics` -- confusion matrix, IoU, accuracy, precision, recall;
* :mod:`~dstenv.segment.replay` / :mod:`~dstenv.segment.tune` -- re-running and
  tuning the DST filter on recorded drives;
* :mod:`~dstenv.segment.complete` -- ``dst-complete``, DST plus vehicle boxes;
* :mod:`~dstenv.segment.train`, :mod:`~dstenv.segment.checkpoint` -- ``dstenv train``;
* :mod:`~dstenv.segment.score` -- the one orchestration: segmenters x drives -> counts;
* :mod:`~dstenv.segment.stats`, :mod:`~dstenv.segment.results` -- bootstrap, goals;
* :mod:`~dstenv.segment.benchmark`, :mod:`~dstenv.segment.plan`,
  :mod:`~dstenv.segment.report`, :mod:`~dstenv.segment.real` -- ``dstenv benchmark``
  (``docs/benchmark.md``).

Names are imported lazily, so ``import dstenv.segment`` does not import torch.
"""

from __future__ import annotations

from dstenv._lazy import lazy_attributes

_WHERE = {
    "SEGMENTERS": "registry", "create_segmenter": "registry", "register_segmenter": "registry",
    "Segmenter": "segmenters", "DSTSegmenter": "segmenters", "TorchSegmenter": "segmenters",
    "EnsembleSegmenter": "segmenters",
    "save_checkpoint": "checkpoint", "load_checkpoint": "checkpoint",
    "load_segmenter": "checkpoint",
    "ConfusionMeter": "metrics", "confusion_matrix": "metrics", "iou_per_class": "metrics",
    "mean_iou": "metrics",
}
__all__ = sorted(_WHERE)
__getattr__, __dir__ = lazy_attributes(__name__, _WHERE)
