"""Readers: values from hand-written fixtures and the real sample; bad input -> KittiError."""

from __future__ import annotations

import numpy as np
import pytest

from dstenv.kitti.readers import (
    OBJECT_TYPES,
    KittiError,
    read_calib,
    read_labels,
    read_oxts,
    read_velodyne,
    split_root,
    velodyne_path,
)

from .conftest import FIXTURES

TR_VELO_CAM = np.array([[0, -1, 0, 0], [0, 0, -1, -0.08], [1, 0, 0, -0.27], [0, 0, 0, 1.0]])


@pytest.mark.parametrize("name", ["calib_colons.txt", "calib_plain.txt", "calib_aliases.txt"])
def test_calib_with_and_without_colons_and_aliases(name):
    c = read_calib(FIXTURES / name)
    np.testing.assert_array_equal(c.Tr_velo_cam, TR_VELO_CAM)
    np.testing.assert_array_equal(c.R_rect, np.eye(4))
    assert c.P2[0, 3] == 45.0 and c.P2.shape == (3, 4)
    np.testing.assert_array_equal(c.Tr_imu_velo[:3, 3], [-0.8, 0.3, -0.8])
    # Velodyne (10, 2, -1) -> camera (-2, 1 - 0.08, 10 - 0.27), and back
    p = c.velo_to_rect @ [10.0, 2.0, -1.0, 1.0]
    np.testing.assert_allclose(p[:3], [-2.0, 0.92, 9.73])
    np.testing.assert_allclose(c.rect_to_velo @ p, [10.0, 2.0, -1.0, 1.0])


def test_calib_without_tr_velo_cam_names_file_and_key():
    msg = r"calib_no_tr_velo_cam\.txt: calibration has no Tr_velo_cam"
    with pytest.raises(KittiError, match=msg):
        read_calib(FIXTURES / "calib_no_tr_velo_cam.txt")


def test_calib_short_row_names_line():
    msg = r"calib_short_row\.txt:3: Tr_velo_cam needs 12 values, got 11"
    with pytest.raises(KittiError, match=msg):
        read_calib(FIXTURES / "calib_short_row.txt")


def test_missing_calib_file(tmp_path):
    with pytest.raises(KittiError, match="missing calibration file"):
        read_calib(tmp_path / "nope.txt")


def test_labels_wrong_column_count_names_line():
    msg = r"label_bad_columns\.txt:3: expected 17 label columns, got 16"
    with pytest.raises(KittiError, match=msg):
        read_labels(FIXTURES / "label_bad_columns.txt")


def test_labels_unknown_type():
    with pytest.raises(KittiError, match=r"label_unknown_type\.txt:1: unknown object type 'Bus'"):
        read_labels(FIXTURES / "label_unknown_type.txt")


def test_oxts_wrong_column_count_names_line():
    msg = r"oxts_bad_columns\.txt:2: expected 30 OXTS columns, got 29"
    with pytest.raises(KittiError, match=msg):
        read_oxts(FIXTURES / "oxts_bad_columns.txt")


def test_velodyne_roundtrip_and_truncated(tmp_path):
    pts = np.arange(40, dtype=np.float32).reshape(10, 4)
    pts[:, 3] = np.linspace(0.0, 1.0, 10)  # reflectance in [0, 1]
    pts.tofile(tmp_path / "000000.bin")
    np.testing.assert_array_equal(read_velodyne(tmp_path / "000000.bin"), pts)
    # x, y, z only (12 bytes a point) whose size happens to be a multiple of 16: the
    # fourth column is then a coordinate, out of reflectance's range
    xyz = np.tile(np.array([5.0, -3.0, 2.5], np.float32), 8)
    xyz.tofile(tmp_path / "xyz.bin")
    with pytest.raises(KittiError, match=r"xyz\.bin: reflectance outside \[0, 1\]"):
        read_velodyne(tmp_path / "xyz.bin")
    (tmp_path / "000001.bin").write_bytes(pts.tobytes()[:-6])  # 154 bytes
    msg = r"000001\.bin: 154 bytes is not a positive multiple of 16"
    with pytest.raises(KittiError, match=msg):
        read_velodyne(tmp_path / "000001.bin")
    (tmp_path / "000002.bin").write_bytes(b"")
    with pytest.raises(KittiError, match=r"000002\.bin: 0 bytes"):
        read_velodyne(tmp_path / "000002.bin")
    with pytest.raises(KittiError, match=r"000003\.bin: missing Velodyne scan"):
        read_velodyne(tmp_path / "000003.bin")
    far = pts.copy()
    far[6, 1] = 1e30  # finite but no LIDAR return: the grids' indices would overflow
    far.tofile(tmp_path / "000004.bin")
    with pytest.raises(KittiError, match=r"000004\.bin: point 6 lies 1e\+30 m from the sensor"):
        read_velodyne(tmp_path / "000004.bin")


def test_split_root_accepts_both_levels(tiny_root, tmp_path):
    assert split_root(tiny_root) == tiny_root / "training"
    assert split_root(tiny_root / "training") == tiny_root / "training"
    with pytest.raises(KittiError, match="no KITTI tracking data"):
        split_root(tmp_path)


# ---- the real sample -------------------------------------------------------------


def test_real_point_counts(real_root):
    split = split_root(real_root)
    counts = []
    for f in range(40):
        path = velodyne_path(split, "0003", f)
        pts = read_velodyne(path)
        assert pts.shape == (path.stat().st_size // 16, 4)
        counts.append(len(pts))
    assert counts[0] == 115267  # 1844272 bytes / 16
    assert 100_000 < min(counts) and max(counts) < 130_000  # an HDL-64E sweep
    pts = read_velodyne(velodyne_path(split, "0003", 0))
    assert 0.0 <= pts[:, 3].min() and pts[:, 3].max() <= 1.0  # reflectance


def test_real_labels_and_calib(real_root):
    split = split_root(real_root)
    lab = read_labels(split / "label_02" / "0003.txt")
    assert len(lab) == 250
    dc = lab.is_dontcare
    assert dc.sum() == 142
    # DontCare rows: track -1, *dimensions* -1000 and location (-10, -1, -1)
    assert np.all(lab.track[dc] == -1) and np.all(lab.hwl[dc] == -1000)
    np.testing.assert_array_equal(lab.location[dc], np.tile([-10.0, -1.0, -1.0], (142, 1)))
    assert set(lab.track[~dc]) == {0, 1, 2, 3}
    assert np.all(lab.type[~dc] == OBJECT_TYPES.index("Car"))
    np.testing.assert_allclose(lab.hwl[4], [1.381664, 1.510562, 4.101504])  # h, w, l (row 5)
    c = read_calib(split / "calib" / "0003.txt")
    assert c.Tr_velo_cam[0, 1] == pytest.approx(-0.9999714)
    assert c.Tr_imu_velo[0, 3] == pytest.approx(-0.8086759)


def test_calib_with_a_key_twice_names_both_lines(tmp_path):
    from dstenv.kitti.readers import read_calib

    lines = (FIXTURES / "calib_plain.txt").read_text().splitlines()
    p2 = next(line for line in lines if line.startswith("P2"))
    (tmp_path / "c.txt").write_text("\n".join([*lines, p2]) + "\n")
    with pytest.raises(KittiError, match=rf"c\.txt:{len(lines) + 1}: P2 again \(first on line "):
        read_calib(tmp_path / "c.txt")
    # two spellings of one matrix were read silently, the later one winning (attack 14)
    tr = next(line for line in lines if line.startswith("Tr_velo_cam"))
    (tmp_path / "d.txt").write_text("\n".join([*lines, tr.replace("Tr_velo_cam",
                                                                  "Tr_velo_to_cam")]) + "\n")
    with pytest.raises(KittiError, match=rf"d\.txt:{len(lines) + 1}: Tr_velo_to_cam is "
                                         r"Tr_velo_cam of line \d+ again \(another spelling"):
        read_calib(tmp_path / "d.txt")



def _label_file(tmp_path, rows):
    path = tmp_path / "0001.txt"
    path.write_text("\n".join(rows) + "\n")
    return path


_CAR = "0 0 0.0 500.0 150.0 700.0 250.0 1.5 1.7 4.2 2.0 1.6 10.0 -1.57"


def test_labels_a_track_twice_in_one_frame_or_negative_is_named(tmp_path):
    twice = _label_file(tmp_path, [f"3 2 Car {_CAR}", f"3 4 Van {_CAR}", f"3 2 Car {_CAR}"])
    with pytest.raises(KittiError, match=r"0001\.txt:3: track 2 appears twice in frame 3 "
                                         r"\(also line 1\)"):
        read_labels(twice)
    neg = _label_file(tmp_path, [f"3 -1 Car {_CAR}"])
    with pytest.raises(KittiError, match=r"0001\.txt:1: negative track id -1 on a Car"):
        read_labels(neg)
    # DontCare regions share track -1, and one track in two frames is a track
    ok = _label_file(tmp_path, [f"3 -1 DontCare {_CAR}", f"3 -1 DontCare {_CAR}",
                                f"3 2 Car {_CAR}", f"4 2 Car {_CAR}"])
    assert read_labels(ok).track.tolist() == [-1, -1, 2, 2]


def test_labels_person_bom_and_the_line_of_a_bad_box(tmp_path):
    lab = _label_file(tmp_path, [f"0 1 Person {_CAR}"])
    lab.write_bytes(b"\xef\xbb\xbf" + lab.read_bytes())  # a UTF-8 byte-order mark
    got = read_labels(lab)
    assert OBJECT_TYPES[int(got.type[0])] == "Person" and got.frame.tolist() == [0]
    big = _CAR.replace("1.5 1.7 4.2", "1.5 1.7 42.0")
    bad = _label_file(tmp_path, [f"0 1 Car {_CAR}", "", "", f"1 1 Car {big}"])
    with pytest.raises(KittiError, match=r"0001\.txt:4: implausible box size"):
        read_labels(bad)


def test_oxts_angles_in_degrees_are_named(tmp_path):
    row = ["49.0", "8.4", "110.0", "0.01", "0.02", "1.2"] + ["0"] * 24
    good = tmp_path / "good.txt"
    good.write_text(" ".join(row) + "\n")
    assert read_oxts(good).shape == (1, 30)
    deg = tmp_path / "deg.txt"
    deg.write_text(" ".join(row[:5] + ["68.75"] + row[6:]) + "\n")
    with pytest.raises(KittiError, match=r"deg\.txt:1: roll, pitch, yaw = .* radians"):
        read_oxts(deg)


def test_calib_translation_in_centimetres_is_named(tmp_path):
    text = (FIXTURES / "calib_colons.txt").read_text()
    lines = []
    for line in text.splitlines():
        if line.startswith("Tr_velo_cam"):
            key, vals = line.split(":", 1)
            v = [float(x) for x in vals.split()]
            v[3], v[7], v[11] = v[3] * 100, v[7] * 100, v[11] * 100
            line = f"{key}: " + " ".join(str(x) for x in v)
        lines.append(line)
    cm = tmp_path / "calib.txt"
    cm.write_text("\n".join(lines) + "\n")
    with pytest.raises(KittiError, match=r"calib\.txt: Tr_velo_cam translates by .* "
                                         r"\(translations are metres\)"):
        read_calib(cm)
    bom = tmp_path / "bom.txt"
    bom.write_bytes(b"\xef\xbb\xbf" + text.encode())
    np.testing.assert_array_equal(read_calib(bom).Tr_velo_cam, TR_VELO_CAM)
