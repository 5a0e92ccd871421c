"""Shared fixtures of the segment tests: synthetic frames in the dataset dict layout."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from dstenv.frame import IGNORE_INDEX


class SyntheticFrames(torch.utils.data.Dataset):
    """Blobs of classes with a noisy 10-channel BetP-like input.

    ``x[:5]`` is a noisy softmax of the one-hot labels (so argmax is mostly right),
    ``x[5:]`` the same shifted by one column (a "previous" frame); a border of
    ignore labels and a random visible mask exercise the masks.
    """

    def __init__(
        self, n: int = 8, shape: tuple[int, int] = (32, 32), seed: int = 0, noise: float = 1.2
    ):
        rng = np.random.default_rng(seed)
        h, w = shape
        self.items = []
        for _ in range(n):
            lab = np.zeros((h, w), dtype=np.int64)
            lab[: h // 3] = 2  # building band
            lab[h // 3 : h // 2] = 1
            for cls in (3, 4, 3, 4):
                i, j = rng.integers(h // 2, h - 4), rng.integers(0, w - 4)
                lab[i : i + 3, j : j + 3] = cls
            onehot = np.eye(5, dtype=np.float32)[lab].transpose(2, 0, 1)
            logits = 2.0 * onehot + noise * rng.standard_normal((5, h, w)).astype(np.float32)
            p = np.exp(logits) / np.exp(logits).sum(0, keepdims=True)
            x = np.concatenate([p, np.roll(p, 1, axis=2)]).astype(np.float32)
            lab[0, :] = IGNORE_INDEX
            vis = rng.random((h, w)) < 0.7
            self.items.append(
                {
                    "x": torch.from_numpy(x),
                    "labels": torch.from_numpy(lab),
                    "visible": torch.from_numpy(vis),
                }
            )

    def __len__(self) -> int:
        return len(self.items)

    def __getitem__(self, i: int) -> dict[str, torch.Tensor]:
        return self.items[i]


@pytest.fixture
def make_frames():
    """Factory fixture: ``make_frames(n, shape=(32, 32), seed=0)`` -> :class:`SyntheticFrames`."""
    return SyntheticFrames
