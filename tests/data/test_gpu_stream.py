"""Simulate without fusion, fuse batched in torch: the frames of the plain pipeline."""

from __future__ import annotations

from itertools import islice

import numpy as np
import pytest
from torch.utils.data import DataLoader

from dstenv.data.gpu_stream import SensorStream, fuse_batches
from dstenv.data.sampling import episode_seeds, iter_frames, scenario_config
from dstenv.pipeline import Pipeline

from .test_end_to_end import TINY


@pytest.mark.parametrize("every,warmup", [(1, 2), (3, 3)])
def test_batched_fusion_of_streams_equals_the_pipeline_frames(every, warmup):
    # 2 streams, episodes of 7 steps, kept steps (2, 5) or (3, 6); every = 3: the paper
    # protocol (fused steps 0, 3, 6; t-1 = the previous fused frame)
    config = scenario_config(TINY, {"protocol": {"update_every": every}})
    ds = SensorStream(config, seed=3, streams=2, episode_length=7, stride=3, warmup=warmup)
    loader = DataLoader(ds, batch_size=None, num_workers=0)
    got = list(islice(fuse_batches(loader), 6))
    assert all(b["x"].shape == (2, 10, 32, 32) for b in got)
    for s in range(2):
        want = list(islice(iter_frames(lambda: Pipeline(config),
                                       episode_seeds(3, "train", (0, 0, s)), 7, 3, warmup), 6))
        for b, f in zip(got, want):
            np.testing.assert_allclose(b["x"][s, :5].numpy(), f.pignistic, atol=1e-5)
            np.testing.assert_allclose(b["x"][s, 5:].numpy(), f.pignistic_prev, atol=1e-5)
            np.testing.assert_array_equal(b["labels"][s].numpy(), f.labels)
            np.testing.assert_array_equal(b["visible"][s].numpy(), f.visible)


def test_pipeline_without_fusion_gives_inputs_only():
    p = Pipeline(scenario_config(TINY), fuse=False)
    f = p.reset(4)
    f = p.step()
    assert f.pignistic is None and f.pignistic_prev is None
    q = Pipeline(scenario_config(TINY))
    q.reset(4)
    g = q.step()
    np.testing.assert_array_equal(f.sensor, g.sensor)
    np.testing.assert_array_equal(f.labels, g.labels)


def test_sensor_stream_rejects_bad_arguments():
    with pytest.raises(ValueError, match="streams must be >= 1"):
        SensorStream(TINY, streams=0)
    with pytest.raises(ValueError, match="unknown split"):
        SensorStream(TINY, split="nope")
