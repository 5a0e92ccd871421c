"""Direct chunk encoding: the same bytes h5py's gzip + fletcher32 filters store."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from dstenv.data.codec import encode_chunk, fletcher32
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
            assert mask == 0 and stored == encode_chunk(a[i], compression, level)


def test_stride1_prev_chunk_is_shared_and_reads_back(tmp_path, frames, shard_attrs):
    # frames of one episode at stride 1: prev of frame t is pignistic of frame t-1
    for t in range(1, len(frames)):
        frames[t].pignistic_prev = frames[t - 1].pignistic.copy()
    for threads in (0, 1):
        path = tmp_path / f"s{threads}.h5"
        with ShardWriter(path, shard_attrs, threads=threads) as w:
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
