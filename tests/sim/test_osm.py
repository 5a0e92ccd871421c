"""OSM loader: widths from tags, clipped ways, errors, georeference, shared extracts."""

import bz2
import math

import numpy as np
import pytest

from dstenv.sim import World
from dstenv.sim.lanes import LaneKind
from dstenv.sim.osm import load_osm
from dstenv.sim.osm_xml import EARTH_RADIUS, latlon_to_mercator
from dstenv.sim.types import MapClass
from shared_data import SHARED_DATA

SHARED = SHARED_DATA / "osm"
DEG = math.pi * EARTH_RADIUS / 180.0  # [m] per degree of longitude at lat 0 (scale 1)

TINY = """<?xml version='1.0' encoding='UTF-8'?>
<osm version="0.6">
  <bounds minlat="-0.0006" minlon="-0.0006" maxlat="0.0006" maxlon="0.0006"/>
  <node id="1" lat="0" lon="-0.0005"/>
  <node id="2" lat="0" lon="0"/>
  <node id="3" lat="0" lon="0.0005"/>
  <node id="4" lat="0.0005" lon="0"/>
  <node id="5" lat="-0.0005" lon="0"/>
  <node id="6" lat="0.00015" lon="0.00015"/>
  <node id="7" lat="0.00015" lon="0.00025"/>
  <node id="8" lat="0.00025" lon="0.00025"/>
  <node id="9" lat="0.00025" lon="0.00015"/>
  <way id="10"><nd ref="1"/><nd ref="2"/><nd ref="3"/>
    <tag k="highway" v="residential"/><tag k="width" v="8 m"/></way>
  <way id="11"><nd ref="2"/><nd ref="4"/>
    <tag k="highway" v="residential"/><tag k="lanes" v="2"/></way>
  <way id="12"><nd ref="2"/><nd ref="5"/><nd ref="999"/>
    <tag k="highway" v="residential"/><tag k="lanes" v="1"/><tag k="oneway" v="yes"/></way>
  <way id="13"><nd ref="6"/><nd ref="7"/><nd ref="8"/><nd ref="9"/><nd ref="6"/>
    <tag k="building" v="yes"/></way>
</osm>
"""


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    path = tmp_path_factory.mktemp("osm") / "tiny.osm"
    path.write_text(TINY)
    return path


def _run_length(cells: np.ndarray, value: int) -> int:
    return int((cells == value).sum())


def test_widths_from_tags_in_raster_cells(tiny):
    m = load_osm(tiny, resolution=0.2, lane_width=3.0)
    x0, y0 = m.origin

    def col(x):
        return m.raster[:, int((x - x0) / m.resolution)]

    def row(y):
        return m.raster[int((y - y0) / m.resolution), :]

    assert abs(_run_length(col(-40.0), MapClass.ROAD) - 8.0 / 0.2) <= 1  # width = 8 m
    assert abs(_run_length(row(+35.0), MapClass.ROAD) - 2 * 3.0 / 0.2) <= 1  # 2 lanes x 3 m
    assert abs(_run_length(row(-35.0), MapClass.ROAD) - 1 * 3.0 / 0.2) <= 1  # clipped way kept
    # building of 0.0001 deg = 11.1 m square around (22.3 m, 22.3 m)
    c = 0.0002 * DEG
    assert m.raster[int((c - y0) / m.resolution), int((c - x0) / m.resolution)] == MapClass.BUILDING
    assert len(m.buildings) == 1
    p, q = m.buildings[0], np.roll(m.buildings[0], -1, 0)
    area = 0.5 * abs((p[:, 0] * q[:, 1] - p[:, 1] * q[:, 0]).sum())  # shoelace
    assert area == pytest.approx((0.0001 * DEG) ** 2, rel=1e-3)
    # everything else is intermediate
    corner = m.raster[int((-30 - y0) / m.resolution), int((-30 - x0) / m.resolution)]
    assert corner == MapClass.INTERMEDIATE


def test_dangling_node_is_clipped_not_fatal(tiny):
    m = load_osm(tiny)
    assert m.meta["clipped_ways"] == 1 and m.meta["dropped_ways"] == 0
    net = m.lanes
    # the one-way clipped street has one lane, running south (away from the junction)
    ends = [net.polyline(k)[-1] for k in np.flatnonzero(net.kind == LaneKind.ROAD)]
    south = [e for e in ends if e[1] < -20]
    assert len(south) == 1 and south[0][1] < -40


def test_lanes_route_through_the_junction(tiny):
    net = load_osm(tiny).lanes
    assert (net.kind == LaneKind.CONNECTOR).sum() > 0
    junction = net.node_xy[np.argmin(np.hypot(*net.node_xy.T))]
    assert np.allclose(junction, 0.0, atol=1e-6)
    assert all(len(net.successors(k)) >= 1 for k in np.flatnonzero(net.kind == LaneKind.CONNECTOR))


def test_georeference_follows_kitti_mercator(tiny):
    m = load_osm(tiny)
    lat0, lon0 = m.meta["latlon_origin"]
    assert (lat0, lon0) == (0.0, 0.0)
    assert m.meta["mercator_scale"] == pytest.approx(1.0)
    mx, my = latlon_to_mercator(0.0, 0.0005, 1.0)
    assert float(mx) == pytest.approx(0.0005 * DEG) and float(my) == pytest.approx(0.0, abs=1e-9)
    scale = math.cos(math.radians(48.0))
    _, my48 = latlon_to_mercator(48.0, 0.0, scale)
    expected = scale * EARTH_RADIUS * math.log(math.tan(138.0 * math.pi / 360))
    assert float(my48) == pytest.approx(expected)


def test_bz2_gives_the_same_map(tiny, tmp_path):
    packed = tmp_path / "tiny.osm.bz2"
    packed.write_bytes(bz2.compress(TINY.encode()))
    a, b = load_osm(tiny), load_osm(packed)
    assert np.array_equal(a.raster, b.raster)


def test_malformed_xml_is_one_line_naming_the_file(tmp_path):
    bad = tmp_path / "bad.osm"
    bad.write_text("<osm><node id='1' lat='0' lon='0'></osm>")
    with pytest.raises(ValueError, match="bad.osm: malformed OSM XML") as exc:
        load_osm(bad)
    assert "\n" not in str(exc.value)
    with pytest.raises(FileNotFoundError, match="missing.osm"):
        load_osm(tmp_path / "missing.osm")


@pytest.mark.parametrize("body", [
    # two nodes at one point; a way of 8 cm; nodes without any way; a building alone
    '<node id="1" lat="46.5" lon="7.5"/><node id="2" lat="46.5" lon="7.5"/>'
    '<way id="10"><nd ref="1"/><nd ref="2"/><tag k="highway" v="residential"/></way>',
    '<node id="1" lat="46.5" lon="7.5"/><node id="2" lat="46.5" lon="7.500001"/>'
    '<way id="10"><nd ref="1"/><nd ref="2"/><tag k="highway" v="residential"/></way>',
    '<node id="1" lat="46.5" lon="7.5"/><node id="2" lat="46.501" lon="7.5"/>',
    '<node id="1" lat="46.5" lon="7.5"/><node id="2" lat="46.5001" lon="7.5"/>'
    '<node id="3" lat="46.5001" lon="7.5001"/><way id="9"><nd ref="1"/><nd ref="2"/>'
    '<nd ref="3"/><nd ref="1"/><tag k="building" v="yes"/></way>',
])
def test_a_map_without_a_drivable_road_is_one_line(tmp_path, body):
    # each of these crashed the interpreter (a segfault in the lane kernels)
    path = tmp_path / "x.osm"
    path.write_text(f'<?xml version="1.0"?><osm version="0.6">{body}</osm>')
    with pytest.raises(ValueError, match="x.osm: no drivable road in the OSM file"):
        load_osm(path)


def test_world_drives_on_a_loaded_map(tiny):
    w = World({"map": {"kind": "osm", "osm_file": str(tiny)},
               "traffic": {"cars": 2, "pedestrians": 2, "cyclists": 0}}, seed=0)
    for _ in range(100):
        w.step()
        assert not w.collision
    assert w.route_progress > 10.0


@pytest.mark.parametrize("name", ["kirchberg-small.osm", "west-oakland.osm.bz2"])
def test_shared_extracts(name):
    path = SHARED / name
    if not path.is_file():
        pytest.skip(f"shared OSM extract {name} not available")
    m = load_osm(path)
    counts = np.bincount(m.raster.ravel(), minlength=4)
    assert counts[MapClass.ROAD] > 0 and counts[MapClass.BUILDING] > 0
    assert len(m.buildings) > 10 and (m.lanes.kind == LaneKind.ROAD).sum() > 20
    vehicle = np.flatnonzero(m.lanes.kind <= LaneKind.CONNECTOR)
    road = np.vstack([m.lanes.polyline(k) for k in vehicle])
    x0, x1, y0, y1 = m.bounds
    assert ((road[:, 0] >= x0) & (road[:, 0] < x1) & (road[:, 1] >= y0) & (road[:, 1] < y1)).all()
