"""Training-time augmentation of a batch ``{"x": (B, C, H, W), "labels": (B, H, W), ...}``:
a random crop and a random left-right mirror, both drawn from the caller's seeded
``torch.Generator`` (so an epoch's batches are reproducible). Tensors of fewer than 3
dimensions (per-sample scalars) pass through unchanged."""

from __future__ import annotations

import torch

__all__ = ["random_crop", "random_flip"]


def random_crop(
    batch: dict[str, torch.Tensor], size: int, gen: torch.Generator
) -> dict[str, torch.Tensor]:
    """One random ``size x size`` window, the same for every sample of the batch and for
    ``x (B, C, H, W)`` and ``labels (B, H, W)`` (a side below ``size`` is kept whole);
    ``size <= 0``, or a grid within it, returns ``batch`` and draws nothing."""
    h, w = batch["labels"].shape[-2:]
    if size <= 0 or (size >= h and size >= w):
        return batch
    ch, cw = min(size, h), min(size, w)
    i = int(torch.randint(0, h - ch + 1, (1,), generator=gen))
    j = int(torch.randint(0, w - cw + 1, (1,), generator=gen))
    return {k: (v[..., i : i + ch, j : j + cw] if v.dim() >= 3 else v) for k, v in batch.items()}


def random_flip(
    batch: dict[str, torch.Tensor], p: float, gen: torch.Generator
) -> dict[str, torch.Tensor]:
    """Mirror each sample left-right with probability ``p`` (``x (B, C, H, W)``,
    ``labels (B, H, W)``: the last axis); ``p == 0`` draws nothing from ``gen``."""
    if p <= 0:
        return batch
    pick = torch.rand(batch["labels"].shape[0], generator=gen) < p
    return {k: (torch.where(pick.view(-1, *([1] * (v.dim() - 1))), v.flip(-1), v)
                if v.dim() >= 3 else v) for k, v in batch.items()}
