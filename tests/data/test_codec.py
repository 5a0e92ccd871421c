"""Direct chunk encoding: the same bytes h5py's gzip + fletcher32 filters store."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from dstenv.data.codec import (
    class_counts, encode_chunk, fletcher32, observed_is, quantize, quantize_cells,
)
from dstenv.data.shards import ShardReader, ShardWriter


def test_fletcher32_hand_values():
    # words 0x0102, 0x0304: sum1 = 0x0406, sum2 = 0x0102 + 0x0406 = 0x0508
    assert fletcher32(bytes([1, 2, 3, 4])) == 0x0508_0406
    # odd length: the last byte is the high byte of a word: 0x0500
    assert fletcher32(bytes([1, 2, 3, 4, 5])) == ((0x0508 + 0x0906) << 16) | 0x0906
    assert fletcher32(b"") == 0
    # 0xFFFF words fold to 0xFFFF (ones' complement), never to 0
    assert fletcher32(b"\xff\xff") == 0xFFFF_FFFF


@pytest.mark.parametrize("compression,level", [("gzip", 1), ("gzip", 3), ("gzip", 6),
                                               (None, None)])
def test_chunks_match_h5py_filters(tmp_path, compression, level):
    rng = np.random.default_rng(0)
    a = (rng.random((3, 5, 37, 29)) < 0.2) * rng.integers(0, 256, (3, 5, 37, 29))
    a = a.astype(np.uint8)
    with h5py.File(tmp_path / "ref.h5", "w") as f:
        f.create_dataset("x", data=a, chunks=(1, 5, 37, 29), compression=compression,
                         compression_opts=level, fletcher32=True)
    with h5py.File(tmp_path / "ref.h5") as f:
        for i in range(3):
            mask, stored = f["x"].id.read_direct_chunk((i, 0, 0, 0))
            assert mask == 0 and stored == encode_chunk(a[i], compression, level, "zlib")


@pytest.mark.parametrize("level", [0, 1, 3, 6])
def test_isal_chunks_read_back_with_plain_h5py(tmp_path, level):
    # ISA-L deflate: other bytes than zlib, but a standard stream HDF5's filter decodes,
    # with a checksum h5py verifies
    rng = np.random.default_rng(1)
    a = (rng.random((3, 5, 37, 29)) < 0.2) * rng.integers(0, 256, (3, 5, 37, 29))
    a = a.astype(np.uint8)
    with h5py.File(tmp_path / "x.h5", "w") as f:
        ds = f.create_dataset("x", shape=a.shape, chunks=(1, 5, 37, 29), dtype=np.uint8,
                              compression="gzip", compression_opts=level, fletcher32=True)
        for i in range(3):
            ds.id.write_direct_chunk((i, 0, 0, 0), encode_chunk(a[i], "gzip", level, "isal"))
    with h5py.File(tmp_path / "x.h5") as f:
        np.testing.assert_array_equal(f["x"][:], a)
        raw = bytearray(f["x"].id.read_direct_chunk((1, 0, 0, 0))[1])
    raw[len(raw) // 2] ^= 0xFF  # a flipped byte must fail the checksum on read
    with h5py.File(tmp_path / "x.h5", "r+") as f:
        f["x"].id.write_direct_chunk((1, 0, 0, 0), bytes(raw))
    with h5py.File(tmp_path / "x.h5") as f, pytest.raises(OSError):
        f["x"][1]


def test_encode_chunk_rejects_unknown_engine():
    with pytest.raises(ValueError, match="deflate engine 'zstd'"):
        encode_chunk(np.zeros(4, np.uint8), "gzip", 1, "zstd")


def test_quantize_matches_numpy_expression_including_ties():
    rng = np.random.default_rng(2)
    # exact half-way values k + 0.5 (round half to even), out-of-range values, random
    ties = ((np.arange(255) + 0.5) / 255).astype(np.float32)
    p = np.concatenate([ties, np.float32([-0.5, 0.0, 1.0, 1.5]),
                        rng.random(10_001).astype(np.float32)]).reshape(2, -1)
    expected = np.rint(np.clip(p, 0.0, 1.0) * 255).astype(np.uint8)
    np.testing.assert_array_equal(quantize(p, 255), expected)
    assert quantize(p, 255).shape == p.shape
    for bad in (np.nan, np.inf):
        q = p.copy()
        q[1, 7] = bad
        with pytest.raises(ValueError, match="NaN/inf"):
            quantize(q, 255)


def test_class_counts_values_and_bad_label():
    labels = np.array([[0, 1, 1, 4], [255, 4, 4, 2]], np.uint8)
    np.testing.assert_array_equal(class_counts(labels, 5, 255), [1, 2, 1, 0, 3])
    labels[1, 3] = 7
    with pytest.raises(ValueError, match="labels hold value 7; allowed 0..4 and 255"):
        class_counts(labels, 5, 255)


def test_stride1_prev_chunk_is_shared_and_reads_back(tmp_path, frames, shard_attrs):
    # frames of one episode at stride 1: prev of frame t is pignistic of frame t-1
    for t in range(1, len(frames)):
        frames[t].pignistic_prev = frames[t - 1].pignistic.copy()
    # zlib on both sides: a threaded writer deflates with zlib (ISA-L's bytes from
    # worker threads were not reproducible), so the bytes can be compared
    for threads in (0, 1):
        path = tmp_path / f"s{threads}.h5"
        with ShardWriter(path, shard_attrs, threads=threads, deflate="zlib") as w:
            for f in frames:
                w.add(f)
        with h5py.File(path) as h:
            for t in range(1, len(frames)):
                assert (h["pignistic_prev"].id.read_direct_chunk((t, 0, 0, 0))
                        == h["pignistic"].id.read_direct_chunk((t - 1, 0, 0, 0)))
        with ShardReader(path) as r:
            r.verify()
            for i, f in enumerate(frames):
                np.testing.assert_allclose(r[i].pignistic_prev, f.pignistic_prev, atol=1 / 510)
    assert (tmp_path / "s0.h5").read_bytes() == (tmp_path / "s1.h5").read_bytes()


@pytest.mark.parametrize("shape", [(256, 256), (12, 10), (13, 7), (1, 1), (37, 29)])
def test_quantize_cells_is_the_cell_major_quantisation(shape):
    # odd sizes, values outside [0, 1] and exact ties (k + 0.5) / 255 round as numpy does
    rng = np.random.default_rng(3)
    p = (rng.random((5, *shape)) * 1.2 - 0.1).astype(np.float32)
    ties = ((np.arange(p.size) % 256 + 0.5) / 255).astype(np.float32).reshape(p.shape)
    p[:, ::2] = ties[:, ::2]
    q = quantize_cells(p, 255)
    assert q.shape == (*shape, 5) and q.dtype == np.uint8 and q.flags.c_contiguous
    np.testing.assert_array_equal(q, quantize(p, 255).transpose(1, 2, 0))
    np.testing.assert_array_equal(q, np.rint(np.clip(p, 0, 1) * np.float32(255))
                                  .astype(np.uint8).transpose(1, 2, 0))
    buf = np.full((*shape, 5), 7, np.uint8)
    assert quantize_cells(p, 255, out=buf) is buf
    np.testing.assert_array_equal(buf, q)
    with pytest.raises(ValueError, match="out must be"):
        quantize_cells(p, 255, out=np.empty((*shape, 4), np.uint8))
    for bad in (np.nan, -np.inf):
        p2 = p.copy()
        p2[2, 0, -1] = bad
        with pytest.raises(ValueError, match="NaN/inf"):
            quantize_cells(p2, 255)
    p[4, -1, -1] = np.inf
    with pytest.raises(ValueError, match="NaN/inf"):
        quantize_cells(p, 255)
    with pytest.raises(ValueError, match=r"needs a \(5, H, W\) grid"):
        quantize_cells(p[:4], 255)


def test_observed_is_visible_mask_for_every_dtype_and_size():
    from dstenv.sensing import visible_mask

    rng = np.random.default_rng(3)
    for shape in ((1, 1), (7, 9), (64, 64), (65, 63)):  # below, at and around 64 lanes
        sensor = rng.integers(0, 3, shape).astype(np.uint8)
        vis = visible_mask(sensor)
        assert observed_is(vis, sensor) and observed_is(vis.astype(np.uint8) * 7, sensor)
        assert observed_is(vis, sensor.astype(np.int64))  # the non-kernel dtype
        for k in (0, sensor.size - 1):  # a flip at either end of the kernel's lanes
            bad = vis.copy().reshape(-1)
            bad[k] ^= True
            bad = bad.reshape(shape)
            assert not observed_is(bad, sensor) and not observed_is(bad, sensor.astype(np.int64))
    assert not observed_is(np.ones((4, 4), bool), np.ones((4, 5), np.uint8))
