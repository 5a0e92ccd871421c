"""Batch augmentation: the crop and the mirror keep inputs and labels together."""

import torch

from dstenv.segment.augment import random_crop, random_flip


def test_flip_mirrors_inputs_and_labels_together():
    x = torch.arange(2 * 3 * 4 * 5, dtype=torch.float32).reshape(2, 3, 4, 5)
    y = torch.arange(2 * 4 * 5).reshape(2, 4, 5)
    batch = {"x": x, "labels": y, "seed": torch.tensor([7, 8])}
    gen = torch.Generator().manual_seed(0)
    assert random_flip(batch, 0.0, gen) is batch
    assert torch.equal(gen.get_state(), torch.Generator().manual_seed(0).get_state())
    out = random_flip(batch, 1.0, gen)
    assert torch.equal(out["x"][:, :, :, 0], x[:, :, :, -1])
    assert torch.equal(out["labels"][:, 2, 0], y[:, 2, -1])
    assert torch.equal(out["seed"], batch["seed"])
    # half the samples: each one flipped whole or not at all, inputs with its labels
    many = {"x": x.repeat(20, 1, 1, 1), "labels": y.repeat(20, 1, 1)}
    out = random_flip(many, 0.5, torch.Generator().manual_seed(1))
    flipped = [bool(torch.equal(out["x"][i], many["x"][i].flip(-1))) for i in range(40)]
    assert 5 < sum(flipped) < 35
    for i in range(40):
        assert torch.equal(out["labels"][i], many["labels"][i].flip(-1) if flipped[i]
                           else many["labels"][i])


def test_crop_takes_one_window_for_inputs_and_labels():
    x = torch.arange(2 * 3 * 6 * 8, dtype=torch.float32).reshape(2, 3, 6, 8)
    y = torch.arange(2 * 6 * 8).reshape(2, 6, 8)
    batch = {"x": x, "labels": y, "seed": torch.tensor([7, 8])}
    gen = torch.Generator().manual_seed(0)
    for size in (0, -1, 8, 20):  # no crop, and nothing drawn
        assert random_crop(batch, size, gen) is batch
    assert torch.equal(gen.get_state(), torch.Generator().manual_seed(0).get_state())
    seen = set()
    for _ in range(30):
        out = random_crop(batch, 4, gen)
        assert out["x"].shape == (2, 3, 4, 4) and out["labels"].shape == (2, 4, 4)
        # the window's top-left cell says where it lies; labels from the same place
        i, j = divmod(int(out["labels"][0, 0, 0]), 8)
        assert torch.equal(out["labels"], y[:, i:i + 4, j:j + 4])
        assert torch.equal(out["x"], x[:, :, i:i + 4, j:j + 4])
        assert torch.equal(out["seed"], batch["seed"])
        seen.add((i, j))
    assert len(seen) > 5 and all(0 <= i <= 2 and 0 <= j <= 4 for i, j in seen)
    again = random_crop(batch, 4, torch.Generator().manual_seed(3))  # seeded
    assert torch.equal(again["x"], random_crop(batch, 4, torch.Generator().manual_seed(3))["x"])
