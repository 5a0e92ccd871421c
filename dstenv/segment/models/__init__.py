"""Segmentation networks (encoder + decoder + head), created by name from :data:`MODELS`.

Each entry maps a name to a builder ``f(in_channels, num_classes, **kwargs) ->
SegmentationModel``; add yours with ``MODELS["name"] = builder``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from dstenv.registry import Registry
from dstenv.segment.models.base import SegmentationHead, SegmentationModel
from dstenv.segment.models.fcn8s import fcn8s_vgg16
from dstenv.segment.models.unet import unet_light, unet_temporal

__all__ = ["MODELS", "build_model", "SegmentationModel", "SegmentationHead", "count_parameters"]

#: model name -> builder ``(in_channels, num_classes, **kwargs) -> SegmentationModel``;
#: the first docstring line of a builder describes it. Each model is also a learned
#: segmenter of :data:`dstenv.segment.registry.SEGMENTERS` (derived, not listed twice).
MODELS: Registry[Callable[..., SegmentationModel]] = Registry("model", "model", {
    "unet-light": unet_light,
    "unet-temporal": unet_temporal,
    "fcn8s-vgg16": fcn8s_vgg16,
})


def build_model(
    name: str, in_channels: int = 10, num_classes: int = 5, **kwargs: Any
) -> SegmentationModel:
    """Create a network by name (see :data:`MODELS`); ``kwargs`` go to its builder."""
    builder = MODELS.get(name)
    try:
        return builder(in_channels=in_channels, num_classes=num_classes, **kwargs)
    except TypeError as exc:
        raise ValueError(f"model {name!r}: bad options {sorted(kwargs)}: {exc}") from None


def count_parameters(model: Any) -> int:
    """Number of trainable parameters."""
    return sum(p.numel() for p in model.parameters() if p.requires_grad)
