"""What the benchmark compares: anything that maps a batch of inputs to a class per cell.

Two kinds:

* :class:`DSTSegmenter` -- the pure-DST baseline: argmax of the pignistic
  probability BetP (input channels 0..4). Its :attr:`~DSTSegmenter.params` say
  which DST parameters produced that BetP; stored frames hold BetP computed with
  the *generation* parameters, so for any other parameters the benchmark replays
  the episode's sensor and GIS grids through a fresh filter
  (:mod:`dstenv.segment.replay`) before calling :meth:`predict`.
* :class:`TorchSegmenter` -- a network from :mod:`dstenv.segment.models` reading
  the stored input as is (the paper's 10 channels: BetP at t and t-1).
"""

from __future__ import annotations

from typing import Any

import torch

from dstenv.dst.params import DSTParams
from dstenv.segment.models import SegmentationModel, build_model

__all__ = ["Segmenter", "DSTSegmenter", "TorchSegmenter"]


class Segmenter:
    """Base class: ``predict(x (B, C, H, W) float32) -> (B, H, W) int64``.

    Attributes:
        name: the registry name (``"dst"``, ``"unet-light"``...).
        label: a human-readable name for tables (e.g. ``"dst (paper)"``).
    """

    name: str = ""
    label: str = ""

    def predict(self, x: torch.Tensor) -> torch.Tensor:  # pragma: no cover - interface
        raise NotImplementedError

    def describe(self) -> dict[str, Any]:
        """JSON-compatible description for reports."""
        return {"name": self.name, "label": self.label}


class DSTSegmenter(Segmenter):
    """Argmax of BetP over :data:`dstenv.dst.CLASSES`.

    Args:
        params: DST parameters that must have produced the BetP it is given.
        name: registry name.
        label: table label; defaults to ``name``.
        info: extra JSON-compatible facts for the report (e.g. the tuning trace).
    """

    def __init__(
        self,
        params: DSTParams,
        name: str = "dst",
        label: str | None = None,
        info: dict | None = None,
    ):
        self.params = params
        self.name = name
        self.label = label or name
        self.info = dict(info or {})

    def predict(self, x: torch.Tensor) -> torch.Tensor:
        if x.dim() != 4 or x.shape[1] < 5:
            raise ValueError(f"DST segmenter needs (B, >=5, H, W) BetP input, got {tuple(x.shape)}")
        return x[:, :5].argmax(1)

    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "params": self.params.to_dict(), **self.info}


class TorchSegmenter(Segmenter):
    """A network created by :func:`dstenv.segment.models.build_model`.

    Args:
        model_name: key of :data:`dstenv.segment.models.MODELS`.
        model_kwargs: builder options (JSON-compatible, stored in checkpoints).
        in_channels, num_classes: network input channels and classes.
        device: where :meth:`predict` runs.
        inputs: what the input channels are, a key of
            :data:`dstenv.data.datasets.INPUTS` (``"fcn10"``: BetP at t and t-1).
    """

    def __init__(
        self,
        model_name: str,
        model_kwargs: dict[str, Any] | None = None,
        in_channels: int = 10,
        num_classes: int = 5,
        device: str | torch.device = "cpu",
        inputs: str = "fcn10",
    ) -> None:
        self.name = model_name
        self.inputs = inputs
        self.label = model_name
        self.model_kwargs = dict(model_kwargs or {})
        self.in_channels = in_channels
        self.num_classes = num_classes
        self.device = torch.device(device)
        self.model: SegmentationModel = build_model(
            model_name, in_channels, num_classes, **self.model_kwargs
        )
        # NHWC: oneDNN's convolutions run 25-40 % faster on the CPU (train step and
        # forward); the state dict keeps the same values and loads into either layout
        self.model.to(device=self.device, memory_format=torch.channels_last)

    def predict(self, x: torch.Tensor) -> torch.Tensor:
        if x.dim() != 4 or x.shape[1] != self.in_channels:
            raise ValueError(
                f"{self.name} needs (B, {self.in_channels}, H, W) input, got {tuple(x.shape)}"
            )
        return self.model.predict(x.to(self.device)).cpu()

    def spec(self) -> dict[str, Any]:
        """JSON-compatible recipe to rebuild the network (stored in checkpoints)."""
        return {
            "model": self.name,
            "model_kwargs": self.model_kwargs,
            "in_channels": self.in_channels,
            "num_classes": self.num_classes,
            "inputs": self.inputs,
        }

    def describe(self) -> dict[str, Any]:
        n = sum(p.numel() for p in self.model.parameters())
        return {**super().describe(), **self.spec(), "parameters": n}
