"""The paper's FCN: VGG-16 FCN-8s (Long, Shelhamer & Darrell) for 10-channel DST input.

Plain torch, no download. A first convolution maps the 10 DST channels (BetP at
t and t-1) to 3, as in the paper, so the VGG-16 body keeps its ImageNet shape and
can take pretrained weights from a local torchvision-layout file
(``vgg16-397923af.pth``: keys ``features.N.*`` and ``classifier.{0,3}.*``), given
as ``vgg16_weights=PATH``. fc6/fc7 are the convolutionalised fully connected
layers, each followed by dropout (the paper trained with keep probability 0.1,
i.e. ``dropout=0.9``; the FCN default is 0.5). Skips from pool3 and pool4 give
the 8-pixel output stride; upsampling layers start as bilinear interpolation.

The full model has about 134 M parameters (fc6 alone 103 M); ``fc_channels``
shrinks fc6/fc7 for small machines and fast tests.
"""

from __future__ import annotations

from pathlib import Path

import torch
from torch import nn

from dstenv.segment.models.base import SegmentationModel

__all__ = ["VGG16Encoder", "FCN8sDecoder", "fcn8s_vgg16", "bilinear_kernel", "load_vgg16_weights"]

_VGG16 = (64, 64, "M", 128, 128, "M", 256, 256, 256, "M", 512, 512, 512, "M", 512, 512, 512, "M")


def bilinear_kernel(channels: int, size: int) -> torch.Tensor:
    """``(channels, channels, size, size)`` weights making a transposed conv bilinear upsampling."""
    factor = (size + 1) // 2
    center = factor - 1 if size % 2 == 1 else factor - 0.5
    og = torch.arange(size, dtype=torch.float32)
    filt1 = 1 - (og - center).abs() / factor
    filt = filt1[:, None] * filt1[None, :]
    w = torch.zeros(channels, channels, size, size)
    w[range(channels), range(channels)] = filt
    return w


def _upsampler(channels: int, factor: int) -> nn.ConvTranspose2d:
    up = nn.ConvTranspose2d(
        channels, channels, 2 * factor, stride=factor, padding=factor // 2, bias=False
    )
    with torch.no_grad():
        up.weight.copy_(bilinear_kernel(channels, 2 * factor))
    return up


class VGG16Encoder(nn.Module):
    """Input conv (C_in -> 3), VGG-16 features, fc6/fc7 as convolutions.

    Returns ``[pool3 (B,256,H/8,W/8), pool4 (B,512,H/16,W/16), fc7 (B,fc,H/32,W/32)]``.
    """

    def __init__(
        self, in_channels: int = 10, fc_channels: int = 4096, dropout: float = 0.5
    ) -> None:
        super().__init__()
        self.input_conv = nn.Conv2d(in_channels, 3, 1)
        layers: list[nn.Module] = []
        cin = 3
        for v in _VGG16:  # same indices as torchvision's vgg16().features
            if v == "M":
                layers.append(nn.MaxPool2d(2, 2))
            else:
                layers += [nn.Conv2d(cin, int(v), 3, padding=1), nn.ReLU(inplace=True)]
                cin = int(v)
        self.features = nn.Sequential(*layers)
        self.fc6 = nn.Conv2d(512, fc_channels, 7, padding=3)
        self.fc7 = nn.Conv2d(fc_channels, fc_channels, 1)
        self.drop6 = nn.Dropout2d(dropout)
        self.drop7 = nn.Dropout2d(dropout)
        self.channels = [256, 512, fc_channels]
        self.stride = 32

    def forward(self, x: torch.Tensor) -> list[torch.Tensor]:
        x = self.input_conv(x)
        taps = []
        for i, layer in enumerate(self.features):
            x = layer(x)
            if i in (16, 23):  # pool3, pool4
                taps.append(x)
        x = self.drop6(torch.relu(self.fc6(x)))
        x = self.drop7(torch.relu(self.fc7(x)))
        return [*taps, x]


class FCN8sDecoder(nn.Module):
    """Score pool3/pool4/fc7, fuse at stride 16 then 8; output ``(B, C, H/8, W/8)`` scores."""

    def __init__(self, channels: list[int], num_classes: int) -> None:
        super().__init__()
        self.score_pool3 = nn.Conv2d(channels[0], num_classes, 1)
        self.score_pool4 = nn.Conv2d(channels[1], num_classes, 1)
        self.score_fr = nn.Conv2d(channels[2], num_classes, 1)
        self.up2 = _upsampler(num_classes, 2)
        self.up_pool4 = _upsampler(num_classes, 2)

    def forward(self, feats: list[torch.Tensor]) -> torch.Tensor:
        pool3, pool4, fc7 = feats
        x = self.up2(self.score_fr(fc7)) + self.score_pool4(pool4)
        return self.up_pool4(x) + self.score_pool3(pool3)


def load_vgg16_weights(encoder: VGG16Encoder, path: str | Path) -> None:
    """Copy torchvision-layout VGG-16 weights into ``encoder`` (features, fc6, fc7).

    Raises:
        FileNotFoundError: if ``path`` does not exist.
        ValueError: if the file is no torch state dict, if a key is missing or a shape
            does not fit (e.g. ``fc_channels`` other than 4096 with a full VGG-16 file).
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"VGG-16 weights not found: {path}")
    try:
        sd = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # a text file, a truncated file, a pickle of other objects
        raise ValueError(f"{path}: not a saved torch state dict ({type(exc).__name__}); "
                         "expected torchvision's vgg16 weights (.pth)") from None
    if not isinstance(sd, dict):
        raise ValueError(f"{path}: holds a {type(sd).__name__}, not a state dict; expected "
                         "torchvision's vgg16 weights (.pth)")
    own = encoder.state_dict()
    new = {}
    for key in own:
        if key.startswith("features."):
            src = sd.get(key)
        elif key.startswith(("fc6.", "fc7.")):
            src = sd.get(key.replace("fc6.", "classifier.0.").replace("fc7.", "classifier.3."))
        else:
            continue
        if src is None:
            raise ValueError(
                f"{path}: missing key for {key!r} (expected a torchvision vgg16 state dict)"
            )
        if src.numel() != own[key].numel():
            raise ValueError(
                f"{path}: {key!r} has {tuple(src.shape)}, the model needs {tuple(own[key].shape)}"
            )
        new[key] = src.reshape(own[key].shape)
    encoder.load_state_dict(new, strict=False)


def fcn8s_vgg16(
    in_channels: int = 10,
    num_classes: int = 5,
    fc_channels: int = 4096,
    dropout: float = 0.5,
    vgg16_weights: str | None = None,
) -> SegmentationModel:
    """The paper's VGG-16 FCN-8s (``fcn8s-vgg16``); see the module docstring."""
    enc = VGG16Encoder(in_channels, fc_channels, dropout)
    if vgg16_weights:
        load_vgg16_weights(enc, vgg16_weights)
    return SegmentationModel(
        enc, FCN8sDecoder(enc.channels, num_classes), _upsampler(num_classes, 8)
    )
