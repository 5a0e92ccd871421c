"""A light U-Net that trains on a CPU in minutes, and its two-stream temporal variant.

``unet-light`` (about 0.47 M parameters with the default ``base=16``, ``depth=3``)
takes the paper's 10-channel input (BetP at t and t-1 stacked). ``unet-temporal``
is the paper's future work: BetP at t and at t-1 first pass through *separate*
convolutional streams, and only their features are merged into the U-Net.
"""

from __future__ import annotations

import torch
from torch import nn

from dstenv.segment.models.base import SegmentationHead, SegmentationModel, conv_block

__all__ = ["UNetEncoder", "TwoStreamEncoder", "UNetDecoder", "unet_light", "unet_temporal"]


class UNetEncoder(nn.Module):
    """Conv blocks with 2x2 max pooling in between.

    Args:
        in_channels: C_in.
        base: channels of the first stage; stage k has ``base * 2**k``.
        depth: number of poolings (the last stage is the bottleneck).

    Returns ``depth + 1`` features, stage k of shape ``(B, base*2**k, H/2**k, W/2**k)``.
    """

    def __init__(self, in_channels: int, base: int = 16, depth: int = 3) -> None:
        super().__init__()
        for key, value, hi in (("base", base, 256), ("depth", depth, 8)):
            if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= hi:
                raise ValueError(f"model_kwargs {key}: an integer in 1..{hi}, got {value!r}")
        if base * 2**depth > 4096:  # the deepest stage's channels: memory grows with them
            raise ValueError(f"model_kwargs base {base} and depth {depth}: the deepest stage "
                             f"would have {base * 2**depth} channels (at most 4096)")
        self.channels = [base * 2**k for k in range(depth + 1)]
        cins = [in_channels, *self.channels[:-1]]
        self.stages = nn.ModuleList(conv_block(a, b) for a, b in zip(cins, self.channels))
        self.pool = nn.MaxPool2d(2)
        self.stride = 2**depth

    def forward(self, x: torch.Tensor) -> list[torch.Tensor]:
        feats = []
        for k, stage in enumerate(self.stages):
            x = stage(x if k == 0 else self.pool(x))
            feats.append(x)
        return feats


class TwoStreamEncoder(nn.Module):
    """Separate convolutional streams for the t and t-1 halves, then a U-Net encoder.

    Args:
        in_channels: C_in, split in two equal halves (t first, then t-1).
        stream: channels of each stream.
        base, depth: as :class:`UNetEncoder`, which receives ``2 * stream`` channels.
    """

    def __init__(self, in_channels: int, stream: int = 12, base: int = 16, depth: int = 3) -> None:
        super().__init__()
        if in_channels % 2:
            raise ValueError(
                f"the temporal model needs an even channel count (t, t-1), got {in_channels}"
            )
        self.half = in_channels // 2
        self.stream_t = conv_block(self.half, stream)
        self.stream_prev = conv_block(self.half, stream)
        self.body = UNetEncoder(2 * stream, base, depth)
        self.channels = self.body.channels
        self.stride = self.body.stride

    def forward(self, x: torch.Tensor) -> list[torch.Tensor]:
        merged = torch.cat(
            [self.stream_t(x[:, : self.half]), self.stream_prev(x[:, self.half :])], 1
        )
        return self.body(merged)


class UNetDecoder(nn.Module):
    """Transposed-conv upsampling, concatenation with the skip, a conv block per stage.

    Args:
        channels: encoder channels fine to coarse.

    Output: ``(B, channels[0], H, W)``.
    """

    def __init__(self, channels: list[int]) -> None:
        super().__init__()
        rev = channels[::-1]
        self.ups = nn.ModuleList(
            nn.ConvTranspose2d(a, b, 2, stride=2) for a, b in zip(rev, rev[1:])
        )
        self.blocks = nn.ModuleList(conv_block(2 * b, b) for b in rev[1:])

    def forward(self, feats: list[torch.Tensor]) -> torch.Tensor:
        x = feats[-1]
        for up, block, skip in zip(self.ups, self.blocks, feats[-2::-1]):
            x = block(torch.cat([up(x), skip], 1))
        return x


def unet_light(
    in_channels: int = 10,
    num_classes: int = 5,
    base: int = 16,
    depth: int = 3,
    dropout: float = 0.1,
    betp_skip: float = 0.0,
) -> SegmentationModel:
    """Light U-Net (``unet-light``, ~0.48 M parameters): trains on a CPU.

    ``betp_skip > 0``: logits on top of DST's (:class:`SegmentationModel`)."""
    enc = UNetEncoder(in_channels, base, depth)
    return SegmentationModel(
        enc, UNetDecoder(enc.channels), SegmentationHead(base, num_classes, dropout), betp_skip
    )


def unet_temporal(
    in_channels: int = 10,
    num_classes: int = 5,
    stream: int = 12,
    base: int = 16,
    depth: int = 3,
    dropout: float = 0.1,
) -> SegmentationModel:
    """U-Net with separate t and t-1 streams (``unet-temporal``)."""
    enc = TwoStreamEncoder(in_channels, stream, base, depth)
    return SegmentationModel(
        enc, UNetDecoder(enc.channels), SegmentationHead(base, num_classes, dropout)
    )
