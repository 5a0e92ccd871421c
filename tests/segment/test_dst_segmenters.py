import numpy as np
import pytest
import torch

from dstenv.dst import CLASSES, DSTParams, PerceptionGridFilter
from dstenv.grid import relative_pose
from dstenv.segment.registry import SEGMENTERS, create_segmenter, register_segmenter
from dstenv.segment.replay import Episode, check_replay, filter_episode
from dstenv.segment.tune import score_params, tune_dst_params

STATIC, NAV, MOVING = CLASSES.index("static"), CLASSES.index("navigable"), CLASSES.index("moving")


def parked_car_episode(steps=(0, 1, 2), T=3, seed=0):
    """A road (GIS 2) seen free everywhere except one cell occupied at every sweep."""
    h = w = 8
    sensor = np.ones((T, h, w), np.uint8)
    sensor[:, 2, 2] = 2
    gis = np.full((T, h, w), 2, np.uint8)
    labels = np.full((len(steps), h, w), NAV, np.uint8)
    labels[:, 2, 2] = STATIC
    return Episode(
        seed,
        sensor,
        gis,
        np.zeros((T, 3)),
        np.array(steps),
        labels,
        np.ones((len(steps), h, w), bool),
        0.33,
    )


def test_dst_argmax_on_spec_reference_case():
    # dst-spec: a road cell seen occupied at every update has BetP(static) ~ .47, .78, .94
    x = filter_episode(parked_car_episode(), DSTParams.default())
    assert x.shape == (3, 10, 8, 8)
    np.testing.assert_allclose(x[1:, STATIC, 2, 2], [0.78, 0.94], atol=0.01)
    np.testing.assert_array_equal(x[0, :5], x[0, 5:])  # no t-1 at step 0: BetP(t) again
    np.testing.assert_array_equal(x[2, 5:], x[1, :5])  # t-1 channels = previous BetP
    pred = create_segmenter("dst").predict(torch.from_numpy(x))
    assert pred[2, 2, 2] == STATIC and (pred[2][np.arange(8) != 2] == NAV).all()


def test_filter_episode_matches_a_plain_filter_loop():
    rng = np.random.default_rng(0)
    T, h, w = 6, 12, 10
    poses = np.cumsum(rng.normal(0, 0.3, (T, 3)), axis=0)
    ep = Episode(
        1,
        rng.integers(0, 3, (T, h, w), dtype=np.uint8),
        rng.integers(0, 4, (T, h, w), dtype=np.uint8),
        poses,
        np.array([2, 5]),
        np.zeros((2, h, w), np.uint8),
        np.ones((2, h, w), bool),
        0.5,
    )
    params = DSTParams.paper()
    f = PerceptionGridFilter((h, w), params, 0.5)
    betps = []
    for t in range(T):
        f.update(ep.sensor[t], ep.gis[t], None if t == 0 else relative_pose(poses[t - 1], poses[t]))
        betps.append(f.pignistic().copy())
    x = filter_episode(ep, params)
    np.testing.assert_array_equal(x[0, :5], betps[2])
    np.testing.assert_array_equal(x[1, 5:], betps[4])
    check_replay(ep, x, ep.labels, params)  # consistent with itself
    with pytest.raises(RuntimeError, match="differs from the stored BetP"):
        check_replay(ep, x + 0.05, ep.labels, params)
    with pytest.raises(RuntimeError, match="other labels"):
        check_replay(ep, x, ep.labels + 1, params)


def test_episode_validation():
    ep = parked_car_episode()
    with pytest.raises(ValueError, match="increase"):
        Episode(
            0, ep.sensor, ep.gis, ep.poses, np.array([2, 1]), ep.labels[:2], ep.visible[:2], 0.33
        )


def test_presets_and_custom_params():
    assert create_segmenter("dst", preset="paper").params == DSTParams.paper()
    assert create_segmenter("dst").label == "dst (default)"
    seg = create_segmenter("dst", params={"alpha": 0.5})
    assert seg.params.alpha == 0.5 and seg.params.sensor_confidence == 0.8
    with pytest.raises(ValueError, match="unknown DST preset"):
        create_segmenter("dst", preset="best")
    with pytest.raises(ValueError, match="needs training episodes"):
        create_segmenter("dst-tuned")
    with pytest.raises(ValueError, match="unknown segmenter"):
        create_segmenter("svm")
    # bad options are named (they raised a TypeError naming a private factory, or torch's
    # assertion / negative-dimension errors)
    with pytest.raises(ValueError, match="segmenter 'dst': unknown option 'bogus'; it takes "
                                         "preset, params"):
        create_segmenter("dst", bogus=1)
    for kw, match in (({"num_classes": -1}, "num_classes must be an integer >= 1"),
                      ({"in_channels": 0}, "in_channels must be an integer >= 1"),
                      ({"device": "tpu"}, "device 'tpu': not a torch device")):
        with pytest.raises(ValueError, match=match):
            create_segmenter("unet-light", **kw)


def test_registry_is_extensible():
    register_segmenter(
        "dst-half", lambda: create_segmenter("dst", params={"alpha": 0.5}), "dst", "test"
    )
    try:
        assert create_segmenter("dst-half").params.alpha == 0.5
        with pytest.raises(ValueError, match="already registered"):
            register_segmenter("dst-half", lambda: None, "dst")
    finally:
        del SEGMENTERS["dst-half"]


def test_tuning_is_deterministic_and_never_worse():
    eps = [parked_car_episode(steps=(0, 1), T=2, seed=s) for s in range(2)]
    start = score_params(eps, DSTParams.default())
    best, trace = tune_dst_params(eps, budget=8, seed=3)
    best2, trace2 = tune_dst_params(eps, budget=8, seed=3)
    assert best == best2 and trace == trace2
    assert len(trace["evaluations"]) <= 8
    assert trace["start_miou"] == pytest.approx(start)
    assert trace["best_miou"] >= start
    assert trace["best_miou"] == pytest.approx(score_params(eps, best))
    seg = create_segmenter("dst-tuned", episodes=eps, budget=4)
    assert seg.name == "dst-tuned" and "tuning" in seg.describe()


def test_dst_free_clears_the_trail_of_a_car_that_left():
    # occupied at sweeps 0-2, seen free at sweep 3: DST still says static there (BetP
    # 0.32 against navigable 0.25); dst-free reads the sweep and says navigable
    ep = parked_car_episode(steps=(0, 1, 2, 3), T=4)
    ep.sensor[3, 2, 2] = 1
    x = filter_episode(ep, DSTParams.default())
    assert create_segmenter("dst").predict(torch.from_numpy(x))[3, 2, 2] == STATIC
    from dstenv.data.inputs import network_input

    free = create_segmenter("dst-free")
    assert free.inputs == "fcn10+sensor" and free.label == "dst-free"
    pred = free.predict(torch.from_numpy(network_input(x, ep.sensor, "fcn10+sensor")))
    assert pred[3, 2, 2] == NAV
    assert (pred[:3, 2, 2] == STATIC).all()  # seen occupied: DST's call stands
    with pytest.raises(ValueError, match="fcn10\\+sensor"):
        free.predict(torch.from_numpy(x))  # BetP alone: no sensor channels


def test_free_space_veto_by_hand():
    from dstenv.segment.segmenters import free_space_veto

    pred = torch.tensor([[[0, 1, 2, 3, 4, 4]]])
    betp = torch.zeros(1, 5, 1, 6)
    betp[0, 0] = torch.tensor([0.1, 0.1, 0.1, 0.3, 0.2, 0.1])  # navigable
    betp[0, 1] = torch.tensor([0.2, 0.2, 0.2, 0.1, 0.2, 0.3])  # non-navigable
    free = torch.tensor([[[True, True, True, True, True, False]]])
    # free ground keeps its class; obstacles on free cells take the larger of
    # navigable / non-navigable (ties: navigable); a cell not seen free keeps its call
    assert free_space_veto(pred, betp, free).tolist() == [[[0, 1, 1, 0, 0, 4]]]
