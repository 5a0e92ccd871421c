"""Shard files: HDF5 containers of labelled frames, readable with ``h5py`` alone.

Format (``format = "dstenv-shard"``, ``format_version = 3``)
------------------------------------------------------------
One shard holds ``N`` :class:`dstenv.frame.Frame` records of one grid shape
``(H, W)``. Every per-frame dataset has ``N`` as its first axis; grids are chunked
one frame per chunk (random access reads exactly one chunk per array; the small
records ``ego_pose``, ``time``, ``seed``, ``step``, ``class_counts`` 64 frames per
chunk), compressed (``gzip``, level 1 by default, or ``lzf``: ~1.5x the bytes and
~2.6x the writer's CPU on stride-10 frames, ``docs/throughput.md``, and not the same
bytes twice: h5py's LZF filter leaves its hash table uninitialised, so ``dstenv
generate`` does not offer it; its shards stay readable) and checksummed
(``fletcher32``: a corrupted chunk raises on read instead of returning wrong
numbers). With gzip the writer deflates the grid chunks itself
(:mod:`dstenv.data.codec`, streams HDF5's built-in filter reads) so that a
``pignistic_prev`` equal to the previous frame's ``pignistic`` (every step kept) is
compressed once; readers see no difference.

===================  ======================  =========================================
dataset              shape, dtype            meaning (axes: :mod:`dstenv.grid`)
===================  ======================  =========================================
``pignistic``        (N, H, W, 5) uint8 or   BetP at t over ``attrs["classes"]``,
                     float32                 cell-major (the 5 classes of a cell
                                             side by side)
``pignistic_prev``   (N, H, W, 5) as above   BetP at t-1 (the paper's FCN input is both)
``labels``           (N, H, W) uint8         class index, or 255 (``IGNORE_INDEX``)
``visible``          (N, H, W) bool          cell observed by this sweep: not
                                             stored from version 3, read as
                                             ``sensor != 0`` (see below)
``sensor``           (N, H, W) uint8         0 unknown, 1 free, 2 occupied
``gis``              (N, H, W) uint8         0 none, 1 building, 2 road, 3 intermediate
``ego_pose``         (N, 3) float64          world ``(x [m], y [m], yaw [rad])``
``time``             (N,) float64            seconds since the episode's reset
``seed``             (N,) int64              episode (map) seed of the frame
``step``             (N,) int64              step index within the episode
``class_counts``     (N, 5) int64            cells of each class in ``labels``
``masses``           (N, 32, H, W) float32   optional raw DST masses (bit layout of
                                             :mod:`dstenv.dst`), never quantised
===================  ======================  =========================================

Version 3 does not store ``visible``: it is by definition the cells whose sensor state
is not unknown (:func:`dstenv.sensing.visible_mask`), and :meth:`ShardReader.get`
derives it from ``sensor`` (with h5py alone: ``f["sensor"][i] != 0``). The writer
refuses a frame whose ``visible`` is anything else, so nothing is lost. Leaving out
the redundant chunk saves ~0.05 ms of the write path per 256 x 256 frame (its deflate,
checksum and chunk write; ``docs/throughput.md``) and ~2 KB (38,943 -> 36,930 B a
frame on the default city, ``docs/write_path.py``). Version 2 stored it,
and version 1 (dstenv before this layout) also stored ``pignistic`` and
``pignistic_prev`` as planes, ``(N, 5, H, W)``; everything else is the same.
:class:`ShardReader` reads all three and returns ``visible`` and ``(5, H, W)``
probabilities either way. Cell-major bytes deflate ~35 % smaller and
~25 % faster (the classes of a cell are correlated); the writer quantises straight
into the cell-major order in one vectorised pass (:func:`dstenv.data.codec.quantize_cells`,
~0.04 ms more per cached 256 x 256 grid than plane order, less than deflate saves;
see ``docs/throughput.md``).

Measured at 256 x 256 at stride 10 (default city, uint8 + ISA-L gzip 1, the
default): 40 and 47 KB per frame on two episodes where version 1 stored 57 and
67 KB; ``dstenv bench data`` prints bytes per frame.

Quantisation: when ``attrs["prob_dtype"] == "uint8"`` the probabilities are stored
as ``q = rint(255 * p)`` and read as ``p' = q / 255``, so ``|p' - p| <= 1/510``
(about 0.00196) per value; the five classes of a cell then sum to 1 only within
``5/510``. ``float32`` storage is exact.

Root attributes (the shard describes itself): ``format``, ``format_version``,
``dstenv_version``, ``classes`` (class names in channel order, from
:data:`dstenv.dst.CLASSES`), ``grid_shape`` ``[H, W]``, ``cell_size`` [m],
``prob_dtype``, ``prob_scale`` (255 or 1), ``has_masses``, ``n_frames``,
``complete`` (always true in a final file), ``seed`` (the shard's task seed),
``config`` (the full pipeline configuration as JSON), and whatever else the
producer passes (e.g. ``split``, ``task``, ``scenario``). Attribute values that are
dicts or lists of non-numbers are stored as JSON strings; their names are listed in
the attribute ``json_attrs``.

Reading with h5py alone::

    with h5py.File("shard-00000.h5") as f:
        p = f["pignistic"][7] / f.attrs["prob_scale"]     # (H, W, 5); version 1: (5, H, W)
        config = json.loads(f.attrs["config"])

Atomicity and determinism: :class:`ShardWriter` writes ``NAME.partial`` and renames
it to ``NAME`` only after a successful close (after ``fsync``), so a killed run never
leaves a file under the final name. No timestamps are stored (``track_times=False``),
so the same frames and attributes give a byte-identical file.

Code layout: constants in :mod:`dstenv.data.format`, :class:`ShardWriter` in
:mod:`dstenv.data.writer`, :class:`ShardReader` in :mod:`dstenv.data.reader`; import
them from here.
"""

from __future__ import annotations

from dstenv.data.format import (
    FORMAT,
    FORMAT_VERSION,
    FRAME_FIELDS,
    N_CLASSES,
    N_MASSES,
    QUANT_MAX_ERROR,
    QUANT_SCALE,
    ShardError,
    class_names,
    partial_path,
)
from dstenv.data.reader import ShardReader
from dstenv.data.writer import ShardWriter

__all__ = [
    "FORMAT",
    "FORMAT_VERSION",
    "QUANT_SCALE",
    "QUANT_MAX_ERROR",
    "N_CLASSES",
    "N_MASSES",
    "FRAME_FIELDS",
    "ShardError",
    "ShardWriter",
    "ShardReader",
    "partial_path",
    "class_names",
]
