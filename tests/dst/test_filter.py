"""PerceptionGridFilter: the temporal rule, ego motion, agreement with the reference."""

import os

import numpy as np
import pytest

from dstenv.dst import M, NUM_SETS, OMEGA, DSTParams, PerceptionGridFilter, pignistic, vacuous
from dstenv.dst import filter as filter_module
from dstenv.dst._kernel import (
    REACHABLE, ROW_PLANES, history_rows, inplace_update, kernel_params, plane_grid,
)
from dstenv.dst.reference import reference_update
from dstenv.grid import GridSpec, relative_pose

FREE_CODE, OCC_CODE, ROAD = 1, 2, 2


def full(shape, code):
    return np.full(shape, code, np.uint8)


def test_free_to_occupied_puts_mass_on_moving():
    f = PerceptionGridFilter((2, 2))
    f.update(full((2, 2), FREE_CODE), full((2, 2), ROAD))
    before = f.masses[M].copy()
    m = f.update(full((2, 2), OCC_CODE), full((2, 2), ROAD))
    assert np.all(before == 0)
    assert np.all(m[M] > 0.5)


def test_occupied_to_free_goes_to_omega():
    p = DSTParams(alpha=0.0)
    f = PerceptionGridFilter((1, 1), p)
    f.update(full((1, 1), OCC_CODE), full((1, 1), 0))
    m_prev = f.masses[:, 0, 0].copy()
    m = f.update(full((1, 1), FREE_CODE), full((1, 1), 0))[:, 0, 0]
    # past O (0.8) x new F (0.8) is conflict O->F: 0.64 goes to Omega
    assert m_prev[28] == pytest.approx(0.8, abs=1e-6)
    assert m[OMEGA] == pytest.approx(0.64 + 0.2 * 0.2, abs=1e-5)
    assert m[M] == 0.0


def test_persistent_occupancy_leaves_moving():
    f = PerceptionGridFilter((1, 1))
    zetas, moving = [], []
    for _ in range(6):
        m = f.update(full((1, 1), OCC_CODE), full((1, 1), ROAD))
        zetas.append(float(f.zeta[0, 0]))
        moving.append(float(f.pignistic()[4, 0, 0]))
        assert m[M, 0, 0] == 0.0  # never seen free: nothing on {M} alone
    assert zetas[-1] == 1.0
    assert moving[-1] < 0.06 < 0.4 < moving[0]
    assert all(b <= a + 1e-6 for a, b in zip(moving[1:], moving[2:]))


def test_conflict_decrements_zeta():
    f = PerceptionGridFilter((1, 1), DSTParams(alpha=0.0))
    for _ in range(3):
        f.update(full((1, 1), OCC_CODE), full((1, 1), ROAD))
    assert f.zeta[0, 0] == 1.0
    f.update(full((1, 1), FREE_CODE), full((1, 1), ROAD))
    assert f.zeta[0, 0] == pytest.approx(1 / 3, abs=1e-6)


@pytest.mark.parametrize("cells", [(1, 0), (0, 3), (-2, 1)])
def test_whole_cell_translation_shifts_exactly(cells):
    spec = GridSpec(16, 16, 0.5)
    rng = np.random.default_rng(0)
    # alpha = 0 and an unreachable gamma_O make an uninformative update the identity
    f = PerceptionGridFilter(spec.shape, DSTParams(alpha=0.0, gamma_occupied=1.0), spec.cell_size)
    sensor = rng.integers(0, 3, spec.shape).astype(np.uint8)
    gis = rng.integers(0, 4, spec.shape).astype(np.uint8)
    f.update(sensor, gis)
    before, zeta = f.masses.copy(), f.zeta.copy()
    di, dj = cells  # the ego moves di cells forward and dj cells left
    unknown = np.zeros(spec.shape, np.uint8)
    no_map = np.zeros(spec.shape, np.uint8)
    after = f.update(unknown, no_map, ego_motion=(di * spec.cell_size, dj * spec.cell_size, 0.0))
    h, w = spec.shape
    for i in range(h):
        for j in range(w):
            si, sj = i - di, j - dj  # forward motion moves content down (larger row)
            if 0 <= si < h and 0 <= sj < w:
                np.testing.assert_allclose(after[:, i, j], before[:, si, sj], atol=1e-6)
                assert f.zeta[i, j] == zeta[si, sj]
            else:
                assert after[OMEGA, i, j] == 1.0 and f.zeta[i, j] == 0.0


def test_rotation_by_quarter_turn():
    f = PerceptionGridFilter((9, 9), DSTParams(alpha=0.0, gamma_occupied=1.0), cell_size=1.0)
    sensor = np.zeros((9, 9), np.uint8)
    sensor[2, 4] = OCC_CODE  # 2 m ahead
    f.update(sensor, np.zeros((9, 9), np.uint8))
    m = f.update(np.zeros((9, 9), np.uint8), np.zeros((9, 9), np.uint8), (0.0, 0.0, np.pi / 2))
    # after turning left by 90 degrees the obstacle is 2 m to the right: row 4, column 6
    assert m[28, 4, 6] == pytest.approx(0.8, abs=1e-6)
    assert m[OMEGA, 2, 4] == 1.0


def test_matches_reference_over_random_sequence():
    rng = np.random.default_rng(7)
    shape = (24, 20)
    # the last preset makes free-on-building a total conflict (K = 1: vacuous m_sm)
    presets = (DSTParams.default(), DSTParams.paper(), DSTParams(0.7, 0.9, 0.3, 0.5, 0.2, 0.4, 0.3),
               DSTParams(sensor_confidence=1.0, map_confidence=1.0))
    for params in presets:
        f = PerceptionGridFilter(shape, params, cell_size=0.4)
        m_ref, z_ref = vacuous(shape), np.zeros(shape, np.float32)
        for _ in range(12):
            sensor = rng.integers(0, 3, shape).astype(np.uint8)
            gis = rng.integers(0, 4, shape).astype(np.uint8)
            motion = (rng.normal(0, 0.6), rng.normal(0, 0.6), rng.normal(0, 0.2))
            m = f.update(sensor, gis, motion)
            m_ref, z_ref = reference_update(m_ref, z_ref, sensor, gis, params, 0.4, motion)
            np.testing.assert_allclose(m, m_ref, atol=2e-6)
            np.testing.assert_allclose(f.zeta, z_ref, atol=1e-6)
            np.testing.assert_allclose(f.pignistic(), pignistic(m_ref), atol=2e-6)
        assert np.all(m >= 0) and np.all(m[0] == 0)
        np.testing.assert_allclose(m.sum(0), 1.0, atol=1e-5)
        unreachable = np.setdiff1d(np.arange(NUM_SETS), REACHABLE)
        assert np.all(m[unreachable] == 0)


def test_reset_and_determinism():
    rng = np.random.default_rng(3)
    seq = [(rng.integers(0, 3, (8, 8)).astype(np.uint8),
            rng.integers(0, 4, (8, 8)).astype(np.uint8)) for _ in range(5)]
    f = PerceptionGridFilter((8, 8))
    first = [f.update(s, g, (0.2, 0.1, 0.05)) for s, g in seq]
    f.reset()
    assert np.all(f.masses[OMEGA] == 1.0) and np.all(f.zeta == 0)
    np.testing.assert_allclose(f.pignistic(), 0.2)
    second = [f.update(s, g, (0.2, 0.1, 0.05)) for s, g in seq]
    for a, b in zip(first, second):
        assert np.array_equal(a, b)


@pytest.mark.parametrize("in_place", [False, True])
def test_large_rotation_and_leaving_the_grid(in_place, monkeypatch):
    # runs of consecutive source cells are short under a large turn, and a long jump
    # makes every cell come from outside (the vacuous pad); both must match the reference,
    # with the double buffer and in place (a turn of 2.5 rad needs a ring of most rows)
    if in_place:
        monkeypatch.setattr(filter_module, "IN_PLACE_MIN_CELLS", 0)
    rng = np.random.default_rng(11)
    shape, params = (40, 37), DSTParams.default()
    f = PerceptionGridFilter(shape, params, cell_size=0.5)
    m_ref, z_ref = vacuous(shape), np.zeros(shape, np.float32)
    for motion in [(0.3, -0.2, 1.1), (0.0, 0.0, -2.5), (100.0, 0.0, 0.0), None, (1.0, 2.0, 0.0)]:
        sensor = rng.integers(0, 3, shape).astype(np.uint8)
        gis = rng.integers(0, 4, shape).astype(np.uint8)
        m = f.update(sensor, gis, motion)
        m_ref, z_ref = reference_update(m_ref, z_ref, sensor, gis, params, 0.5, motion)
        np.testing.assert_allclose(m, m_ref, atol=2e-6)
        np.testing.assert_array_equal(f.zeta, z_ref)


@pytest.mark.skipif((os.cpu_count() or 1) < 2, reason="a single CPU")
def test_threads_give_identical_results():
    rng = np.random.default_rng(5)
    shape = (33, 48)
    one, two = PerceptionGridFilter(shape), PerceptionGridFilter(shape, threads=2)
    for _ in range(4):
        sensor = rng.integers(0, 3, shape).astype(np.uint8)
        gis = rng.integers(0, 4, shape).astype(np.uint8)
        motion = (rng.normal(0, 0.6), rng.normal(0, 0.6), rng.normal(0, 0.2))
        assert np.array_equal(one.update(sensor, gis, motion), two.update(sensor, gis, motion))
        assert np.array_equal(one.zeta, two.zeta)
        assert np.array_equal(one.pignistic(), two.pignistic())


@pytest.mark.skipif((os.cpu_count() or 1) < 2, reason="a single CPU")
@pytest.mark.parametrize("motion, ring, desc", [
    ((0.0, 0.0, 0.3), True, False),     # a turn: sources behind the current row
    ((0.0, 0.0, -0.3), True, False),
    ((0.33, 0.02, 0.004), False, True),  # forward at 10 Hz: rows bottom-up, no ring
    ((-2.0, 0.5, 0.05), False, False),   # sources ahead of the rows in ascending order
    ((0.5, 0.0, 0.2), True, True),
])
def test_in_place_update_equals_the_double_buffer(motion, ring, desc, monkeypatch):
    monkeypatch.setattr(filter_module, "IN_PLACE_MIN_CELLS", 0)  # small grids in place too
    # threads=1 updates in place (rows ordered by the motion, a ring of overwritten
    # rows); threads=2 reads one buffer and writes the other: same bits
    rng = np.random.default_rng(9)
    shape = (64, 48)
    geo = np.array([np.cos(motion[2]), np.sin(motion[2]), motion[0], motion[1], 0.33])
    k_hist, down = history_rows(geo, shape)
    assert (k_hist > 0) == ring and down == desc
    one, two = PerceptionGridFilter(shape), PerceptionGridFilter(shape, threads=2)
    for _ in range(3):
        sensor = rng.integers(0, 3, shape).astype(np.uint8)
        gis = rng.integers(0, 4, shape).astype(np.uint8)
        assert np.array_equal(one.update(sensor, gis, motion), two.update(sensor, gis, motion))
        assert np.array_equal(one.zeta, two.zeta)
        assert np.array_equal(one.pignistic(), two.pignistic())


def test_a_wide_short_grid_turning_needs_no_ring_past_its_rows(monkeypatch):
    """Attack 16: a (1, 100000) grid turning sized its ring by the width (29.7 GiB);
    sources further than H - 1 rows are outside the grid, so H rows are enough."""
    monkeypatch.setattr(filter_module, "IN_PLACE_MIN_CELLS", 0)
    shape, params = (3, 400), DSTParams.default()
    geo = np.array([np.cos(0.2), np.sin(0.2), 0.0, 0.0, 0.5])
    assert history_rows(geo, shape)[0] == 3  # (the lag alone: ~40 rows)
    rng = np.random.default_rng(4)
    f = PerceptionGridFilter(shape, params, cell_size=0.5)
    m_ref, z_ref = vacuous(shape), np.zeros(shape, np.float32)
    for motion in [(0.0, 0.0, 0.2), (0.3, 0.1, -0.4)]:
        sensor = rng.integers(0, 3, shape).astype(np.uint8)
        gis = rng.integers(0, 4, shape).astype(np.uint8)
        m = f.update(sensor, gis, motion)
        m_ref, z_ref = reference_update(m_ref, z_ref, sensor, gis, params, 0.5, motion)
        np.testing.assert_allclose(m, m_ref, atol=2e-6)


def test_in_place_update_refuses_a_short_ring():
    # a turn needs the ring; without it the kernel stops instead of reading new values
    h, w = 32, 32
    m = plane_grid(NUM_SETS, (h, w))
    m[OMEGA] = 1.0
    geo = np.array([np.cos(0.3), np.sin(0.3), 0.0, 0.0, 0.33])
    assert history_rows(geo, (h, w))[0] > 0
    with pytest.raises(RuntimeError, match="history ring too short"):
        inplace_update(m, plane_grid(1, (h, w))[0], full((h, w), 1), full((h, w), 2), True, geo,
                       kernel_params(DSTParams.default()), plane_grid(5, (h, w)),
                       np.empty((ROW_PLANES, w), np.float32), 0, False)


@pytest.mark.parametrize("threads", [0, 10_000, 1.5])
def test_bad_thread_count(threads):
    with pytest.raises(ValueError, match="threads must be an integer"):
        PerceptionGridFilter((4, 4), threads=threads)


def test_copy_semantics():
    f = PerceptionGridFilter((4, 4))
    a = f.update(full((4, 4), FREE_CODE), full((4, 4), ROAD))
    view = f.update(full((4, 4), OCC_CODE), full((4, 4), ROAD), copy=False)
    assert a.flags.writeable and a.flags.c_contiguous
    assert not view.flags.writeable
    assert not np.shares_memory(a, view)
    assert view.shape == (NUM_SETS, 4, 4) and f.zeta.shape == (4, 4)
    betp = f.pignistic()
    assert betp.flags.c_contiguous and betp.flags.writeable and betp.shape == (5, 4, 4)
    out = np.zeros_like(betp)
    assert f.pignistic(out) is out and np.array_equal(out, betp)


def test_relative_pose_roundtrip():
    prev = np.array([10.0, -3.0, 0.3])
    dx, dy, dyaw = 2.0, 0.5, 0.1
    c, s = np.cos(prev[2]), np.sin(prev[2])
    pose = np.array([prev[0] + c * dx - s * dy, prev[1] + s * dx + c * dy, prev[2] + dyaw])
    np.testing.assert_allclose(relative_pose(prev, pose), (dx, dy, dyaw), atol=1e-12)


@pytest.mark.parametrize(
    "sensor, gis, match",
    [
        (np.full((4, 4), 3, np.uint8), np.zeros((4, 4), np.uint8), "sensor_states holds code 3"),
        (np.zeros((4, 5), np.uint8), np.zeros((4, 4), np.uint8), r"shape \(4, 4\)"),
        (np.zeros((4, 4), np.uint8), np.full((4, 4), 7, np.uint8), "map_classes holds code 7"),
        (np.zeros((4, 4), np.float32), np.zeros((4, 4), np.uint8), "integer codes"),
        # wide integers are checked before the cast to uint8 (257 used to wrap to 1: free)
        (np.full((4, 4), 257, np.int64), np.zeros((4, 4), np.uint8),
         "sensor_states holds code 257"),
        (np.zeros((4, 4), np.int64), np.full((4, 4), -1, np.int16), "map_classes holds code -1"),
    ],
)
def test_bad_inputs(sensor, gis, match):
    with pytest.raises(ValueError, match=match):
        PerceptionGridFilter((4, 4)).update(sensor, gis)


def test_non_finite_ego_motion_is_rejected():
    with pytest.raises(ValueError, match="ego_motion must be finite"):
        PerceptionGridFilter((4, 4)).update(full((4, 4), 0), full((4, 4), 0), (0.1, np.nan, 0.0))


def test_params_validation_and_presets():
    assert DSTParams.paper().alpha == 0.9 and DSTParams.default().alpha == 0.1
    with pytest.raises(ValueError, match="gamma_occupied"):
        DSTParams(gamma_occupied=6.0)
    with pytest.raises(ValueError, match="unknown DST parameter 'alfa'"):
        DSTParams.from_dict({"alfa": 0.2})
    assert DSTParams.from_dict(DSTParams.paper().to_dict()) == DSTParams.paper()
    for bad in ("x", None, [1], True):
        with pytest.raises(ValueError, match=r"DST parameter alpha: .* is not a number"):
            DSTParams.from_dict({"alpha": bad})


def test_betp_written_into_the_callers_array():
    rng = np.random.default_rng(4)
    shape = (12, 9)
    f, g = PerceptionGridFilter(shape), PerceptionGridFilter(shape)
    for _ in range(3):
        sensor = rng.integers(0, 3, shape).astype(np.uint8)
        gis = rng.integers(0, 4, shape).astype(np.uint8)
        out = np.full((5, *shape), np.nan, np.float32)
        f.update(sensor, gis, (0.4, 0.1, 0.05), betp=out)
        g.update(sensor, gis, (0.4, 0.1, 0.05))
        np.testing.assert_array_equal(out, g.pignistic())
        np.testing.assert_array_equal(f.pignistic(), out)
        np.testing.assert_allclose(out, pignistic(g.masses), atol=2e-6)
    f.reset()
    np.testing.assert_allclose(f.pignistic(), 0.2)
    for bad in (np.empty((5, *shape), np.float64), np.empty((5, 12, 10), np.float32),
                np.empty((5, 9, 12), np.float32).transpose(0, 2, 1)):
        with pytest.raises(ValueError, match="betp must be a writeable C-contiguous float32"):
            f.update(sensor, gis, betp=bad)


@pytest.mark.skipif((os.cpu_count() or 1) < 2, reason="a single CPU")
@pytest.mark.parametrize("shape", [(2, 2), (3, 3), (5, 2), (1, 7)])
def test_in_place_update_on_tiny_grids(shape, monkeypatch):
    monkeypatch.setattr(filter_module, "IN_PLACE_MIN_CELLS", 0)
    # on 2-3 columns a turn can make a run of consecutive sources cross into the next
    # row; the in-place kernel splits it (ring rows are not adjacent in memory)
    rng = np.random.default_rng(2)
    one, two = PerceptionGridFilter(shape, cell_size=1.0), PerceptionGridFilter(shape, threads=2,
                                                                                cell_size=1.0)
    for motion in [(0.0, 0.0, np.pi), (0.4, 1.2, 2.0), (-1.0, 0.0, -1.7), (0.0, 1.0, 0.0)] * 2:
        sensor = rng.integers(0, 3, shape).astype(np.uint8)
        gis = rng.integers(0, 4, shape).astype(np.uint8)
        assert np.array_equal(one.update(sensor, gis, motion), two.update(sensor, gis, motion))
        assert np.array_equal(one.zeta, two.zeta)


def test_in_place_only_for_large_single_thread_grids(monkeypatch):
    big = int(np.ceil(np.sqrt(filter_module.IN_PLACE_MIN_CELLS)))
    assert len(PerceptionGridFilter((big, big))._buf) == 1
    assert len(PerceptionGridFilter((big - 1, big - 1))._buf) == 2
    monkeypatch.setattr(filter_module, "IN_PLACE_MIN_CELLS", 0)
    assert len(PerceptionGridFilter((4, 4))._buf) == 1


@pytest.mark.parametrize("shape", [(64.7, 64), 64, (0, 4), (True, 4), (4, 4, 4)])
def test_a_grid_shape_is_two_integers(shape):
    """Attack 16: (64.7, 64) was truncated to 64; 64 was 'int object is not iterable'."""
    with pytest.raises(ValueError, match="grid shape must be two integers >= 1"):
        PerceptionGridFilter(shape)


def test_params_as_a_dict_are_named():
    with pytest.raises(TypeError, match=r"params: a DSTParams \(DSTParams\.from_dict"):
        PerceptionGridFilter((4, 4), {"alpha": 0.9})
