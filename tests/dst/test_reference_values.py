"""The hand-computed values at the end of dst-spec.md."""

import numpy as np
import pytest

from dstenv.dst import (
    FREE, I, M, N, OMEGA, S, W, DSTParams, PerceptionGridFilter, dempster, map_masses,
    sensor_masses,
)

FREE_CODE, OCC_CODE = 1, 2
BUILDING, ROAD = 1, 2


def cell(code: int) -> np.ndarray:
    return np.full((1, 1), code, np.uint8)


def m_sm(sensor: int, gis: int) -> np.ndarray:
    return dempster(sensor_masses(cell(sensor)), map_masses(cell(gis)))[:, 0, 0]


def test_free_sensor_on_road():
    m = m_sm(FREE_CODE, ROAD)
    assert m[N] == pytest.approx(0.796, abs=1e-6)
    assert m[N | W] == pytest.approx(0.004, abs=1e-6)
    assert m[N | S | M] == pytest.approx(0.199, abs=1e-6)
    assert m[OMEGA] == pytest.approx(0.001, abs=1e-6)
    assert m.sum() == pytest.approx(1.0, abs=1e-6)
    assert np.count_nonzero(m) == 4


def test_occupied_sensor_on_building():
    m = m_sm(OCC_CODE, BUILDING)
    assert m[I] == pytest.approx(0.995, abs=1e-6)
    assert m[I | S | M] == pytest.approx(0.004, abs=1e-6)
    assert m[OMEGA] == pytest.approx(0.001, abs=1e-6)
    assert np.count_nonzero(m) == 3


def test_free_sensor_on_building_conflict_is_normalised():
    m = m_sm(FREE_CODE, BUILDING)
    k = 0.8 * 0.995
    assert 1 - k == pytest.approx(0.204)
    assert m[I] == pytest.approx(0.199 / 0.204, rel=1e-5)
    assert m[FREE] == pytest.approx(0.004 / 0.204, rel=1e-5)
    assert m[OMEGA] == pytest.approx(0.001 / 0.204, rel=1e-5)
    assert m[0] == 0.0


def test_road_seen_free_twice_then_occupied_is_moving():
    f = PerceptionGridFilter((1, 1), DSTParams.default())
    for code in (FREE_CODE, FREE_CODE, OCC_CODE):
        masses = f.update(cell(code), cell(ROAD))
    assert masses[M, 0, 0] == pytest.approx(0.68, abs=0.005)
    assert masses[M, 0, 0] == masses[:, 0, 0].max()
    assert f.pignistic()[4, 0, 0] == pytest.approx(0.75, abs=0.005)


def test_road_always_occupied_becomes_static():
    f = PerceptionGridFilter((1, 1), DSTParams.default())
    expected = [(0.0, 0.47, 0.47), (2 / 3, 0.78, 0.20), (1.0, 0.94, 0.05)]
    for zeta, static, moving in expected:
        f.update(cell(OCC_CODE), cell(ROAD))
        betp = f.pignistic()[:, 0, 0]
        assert f.zeta[0, 0] == pytest.approx(zeta, abs=1e-6)
        assert betp[3] == pytest.approx(static, abs=0.01)  # the spec says "about"
        assert betp[4] == pytest.approx(moving, abs=0.01)
