"""Encoder + decoder + head, the segmentation_models_pytorch layout.

An *encoder* maps the input ``(B, C_in, H, W)`` to a list of feature maps from
fine to coarse; a *decoder* fuses them back to a single map at input resolution;
a *head* turns that map into class logits. :class:`SegmentationModel` chains them
and pads the input to a multiple of the encoder's total stride, so any grid size
works; the logits are cropped back to ``(H, W)``.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

__all__ = ["SegmentationModel", "SegmentationHead", "conv_block"]


def conv_block(cin: int, cout: int) -> nn.Sequential:
    """Two 3x3 convolutions with batch norm and ReLU (the U-Net unit)."""
    return nn.Sequential(
        nn.Conv2d(cin, cout, 3, padding=1, bias=False),
        nn.BatchNorm2d(cout),
        nn.ReLU(inplace=True),
        nn.Conv2d(cout, cout, 3, padding=1, bias=False),
        nn.BatchNorm2d(cout),
        nn.ReLU(inplace=True),
    )


class SegmentationHead(nn.Sequential):
    """Optional dropout, then a 1x1 convolution to ``num_classes`` logits."""

    def __init__(self, cin: int, num_classes: int, dropout: float = 0.0) -> None:
        layers: list[nn.Module] = [nn.Dropout2d(dropout)] if dropout > 0 else []
        super().__init__(*layers, nn.Conv2d(cin, num_classes, 1))


class SegmentationModel(nn.Module):
    """``head(decoder(encoder(x)))`` with padding to the encoder stride.

    Args:
        encoder: module returning ``list[Tensor]`` features, attribute ``stride``
            (total downsampling factor).
        decoder: module taking that list and returning ``(B, C_dec, H', W')``.
        head: module mapping the decoder output to ``(B, num_classes, H', W')``.

        betp_skip: ``w0 > 0`` adds ``w * log(max(BetP_t, 1e-3))`` to the logits, ``w`` a
            learned scalar starting at ``w0``, BetP_t the input's first ``num_classes``
            channels: the network starts from DST's argmax and learns corrections on top
            of it (0, the default: no skip, no extra parameter).

    Shapes: ``x (B, C_in, H, W) float32`` -> logits ``(B, num_classes, H, W)``.
    """

    def __init__(self, encoder: nn.Module, decoder: nn.Module, head: nn.Module,
                 betp_skip: float = 0.0) -> None:
        super().__init__()
        self.encoder = encoder
        self.decoder = decoder
        self.head = head
        if not betp_skip >= 0.0:
            raise ValueError(f"betp_skip must be >= 0, got {betp_skip!r}")
        if betp_skip > 0:
            self.betp_weight = nn.Parameter(torch.tensor(float(betp_skip)))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        h, w = x.shape[-2:]
        s = int(self.encoder.stride)
        ph, pw = (-h) % s, (-w) % s
        if ph or pw:
            # zero input = "no probability anywhere": the same as outside the grid
            x = F.pad(x, (0, pw, 0, ph))
        logits = self.head(self.decoder(self.encoder(x)))
        if logits.shape[-2:] != x.shape[-2:]:
            logits = F.interpolate(logits, size=x.shape[-2:], mode="bilinear", align_corners=False)
        if hasattr(self, "betp_weight"):
            c = logits.shape[1]
            logits = logits + self.betp_weight * torch.log(x[:, :c].clamp_min(1e-3))
        return logits[..., :h, :w]

    @torch.no_grad()
    def predict(self, x: torch.Tensor) -> torch.Tensor:
        """Class per cell, ``(B, H, W) int64``, in eval mode."""
        was_training = self.training
        self.eval()
        try:
            return self.forward(x).argmax(1)
        finally:
            self.train(was_training)
