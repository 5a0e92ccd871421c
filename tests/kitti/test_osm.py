"""OSM alignment: KITTI world poses -> the map's frame; maps that do not fit."""

from __future__ import annotations

import numpy as np
import pytest

from dstenv.grid import GridSpec
from dstenv.kitti.osm import MapAlignment, map_lookup
from dstenv.kitti.readers import KittiError
from dstenv.kitti.sequence import KittiSequence
from dstenv.sim.osm import load_osm
from dstenv.sim.osm_xml import latlon_to_mercator
from dstenv.sim.types import MapClass

from .conftest import FIXTURES, SHARED


def test_alignment_by_hand(tiny_root):
    seq = KittiSequence(tiny_root, "0001")  # first Velodyne at lat 49.0, lon 8.4
    wm = load_osm(FIXTURES / "dangling.osm")
    align = MapAlignment(wm, seq.trajectory)
    lat0, lon0 = wm.meta["latlon_origin"]  # the centre of the extract's bounds
    assert (lat0, lon0) == pytest.approx((49.0005, 8.40075))
    s = wm.meta["mercator_scale"]
    imu = np.subtract(latlon_to_mercator(49.0, 8.4, s), latlon_to_mercator(lat0, lon0, s))
    assert imu == pytest.approx((-54.8, -55.7), abs=0.1)  # 0.00075 deg west, 0.0005 deg south
    # the KITTI origin is the first *Velodyne* position: 0.8 m ahead (east) of the IMU
    # and 0.3 m to its right (south) by the fixture's Tr_imu_velo
    # (the two Mercator scales, cos 49.0 vs cos 49.0005, differ by 1e-5: 8 um on 0.8 m)
    want = imu + [0.8, -0.3]
    np.testing.assert_allclose(align.to_map(np.zeros(2)), want, atol=2e-5)
    # 5 m east in KITTI is 5 m east on the map; the heading carries over
    np.testing.assert_allclose(align.pose(np.array([5.0, 0.0, 0.3])), [want[0] + 5, want[1], 0.3],
                               atol=2e-4)
    assert align.coverage() == 1.0


def test_gis_grid_follows_the_road(tiny_root):
    seq = KittiSequence(tiny_root, "0001")
    gis_fn, note = map_lookup(FIXTURES / "dangling.osm", seq.trajectory)
    assert "100% of the poses on the map" in note
    spec = GridSpec()
    gis = gis_fn(seq.trajectory.poses[2], spec)
    # the residential way runs east along lat 49.0, under the ego's path (ego x = east)
    i0, j0 = spec.ego_cell
    assert (gis[: i0 - 5, j0] == MapClass.ROAD).all()  # straight ahead
    assert gis[i0, j0 + 20] != MapClass.ROAD and gis[i0, j0 - 20] != MapClass.ROAD  # 6.6 m aside


def test_map_elsewhere_and_bad_files(tiny_root, tmp_path):
    seq = KittiSequence(tiny_root, "0001")
    far = tmp_path / "far.osm"
    far.write_text((FIXTURES / "dangling.osm").read_text().replace('lat="49.', 'lat="48.')
                   .replace('minlat="49.', 'minlat="48.').replace('maxlat="49.', 'maxlat="48.'))
    with pytest.raises(KittiError, match=r"far\.osm: the map does not cover the drive"):
        map_lookup(far, seq.trajectory)
    bad = tmp_path / "bad.osm"
    bad.write_text("<osm><node id='1' lat='49.0'")
    with pytest.raises(KittiError, match=r"bad\.osm"):
        map_lookup(bad, seq.trajectory)
    with pytest.raises(KittiError, match=r"missing\.osm"):
        map_lookup(tmp_path / "missing.osm", seq.trajectory)


def test_real_osm_of_another_place(real_root):
    osm = SHARED / ".." / "osm" / "kirchberg-small.osm"
    if not osm.is_file():
        pytest.skip(f"shared OSM extract absent ({osm.resolve()})")
    seq = KittiSequence(real_root, "0003")  # Karlsruhe; the extract is near Ulm
    with pytest.raises(KittiError, match="does not cover the drive"):
        map_lookup(osm, seq.trajectory)
