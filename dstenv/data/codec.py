"""Encoding shard chunks outside HDF5: deflate + Fletcher-32, byte-identical to h5py's filters.

HDF5 stores a chunk of a dataset created with ``compression="gzip"`` (level ``L``)
and ``fletcher32=True`` as ``zlib.compress(raw, L)`` followed by the 4-byte
little-endian Fletcher-32 checksum of the compressed bytes (``H5Zdeflate.c``,
``H5Zfletcher32.c``, ``H5_checksum_fletcher32``). Producing those bytes here and
handing them to ``write_direct_chunk`` lets the writer

* compress a chunk once and store it twice (``pignistic_prev`` of frame ``t`` is
  ``pignistic`` of frame ``t - 1`` when every step is kept),
* compress on a background thread (``zlib`` and the numba checksum release the GIL)
  while the simulation goes on.

The file is still an ordinary HDF5 file: ``h5py`` reads it through its own filter
pipeline and checks the checksum (``tests/data/test_codec.py`` compares the bytes
with chunks h5py wrote itself).
"""

from __future__ import annotations

import zlib

import numba as nb
import numpy as np

__all__ = ["fletcher32", "encode_chunk", "DIRECT_COMPRESSIONS"]

#: compressions whose chunks :func:`encode_chunk` can produce (lzf lives inside h5py only)
DIRECT_COMPRESSIONS = ("gzip", None)


@nb.njit(cache=True, nogil=True)
def _fletcher32(data: np.ndarray) -> np.uint32:
    """``H5_checksum_fletcher32`` of HDF5, bit for bit (big-endian 16-bit words)."""
    mask, sh = np.uint32(0xFFFF), np.uint32(16)
    s1 = np.uint32(0)
    s2 = np.uint32(0)
    n = data.shape[0] // 2
    i = 0
    while n > 0:
        t = n if n <= 360 else 360  # 360 words: the sums cannot overflow 32 bits
        n -= t
        for _ in range(t):
            s1 += (np.uint32(data[i]) << np.uint32(8)) | np.uint32(data[i + 1])
            s2 += s1
            i += 2
        s1 = (s1 & mask) + (s1 >> sh)
        s2 = (s2 & mask) + (s2 >> sh)
    if data.shape[0] % 2:
        s1 += np.uint32(data[i]) << np.uint32(8)
        s2 += s1
        s1 = (s1 & mask) + (s1 >> sh)
        s2 = (s2 & mask) + (s2 >> sh)
    s1 = (s1 & mask) + (s1 >> sh)
    s2 = (s2 & mask) + (s2 >> sh)
    return (s2 << sh) | s1


def fletcher32(buf: bytes) -> int:
    """HDF5's Fletcher-32 checksum of ``buf`` (an unsigned 32-bit int)."""
    return int(_fletcher32(np.frombuffer(buf, np.uint8)))


def encode_chunk(array: np.ndarray, compression: str | None, level: int | None) -> bytes:
    """The stored bytes of one chunk holding ``array`` (C order, any dtype).

    Args:
        array: the chunk's contents (one frame of a dataset).
        compression: ``"gzip"`` or ``None`` (see :data:`DIRECT_COMPRESSIONS`).
        level: gzip level 0-9 (ignored without compression).

    Returns:
        payload + 4-byte little-endian Fletcher-32, as HDF5's filter pipeline would store it.
    """
    raw = np.ascontiguousarray(array).tobytes()
    if compression == "gzip":
        payload = zlib.compress(raw, 6 if level is None else int(level))
    elif compression is None:
        payload = raw
    else:
        raise ValueError(f"cannot encode {compression!r} chunks directly; "
                         f"choose from {DIRECT_COMPRESSIONS}")
    return payload + fletcher32(payload).to_bytes(4, "little")
