"""The fixed parts of the generated ``_fused.py`` (:mod:`dstenv.dst._codegen` writes
them verbatim around the derived row kernels): the ``noalias`` compiler, the warp's
row sources and the drivers that run the row kernels over a grid."""

__all__ = ["DRIVER", "INPLACE_DRIVER", "NOALIAS_COMPILER", "SOURCES"]

NOALIAS_COMPILER = '''
class NoAliasCompiler(CompilerBase):
    """numba's nopython pipeline with every pointer argument marked ``noalias``.

    Lets LLVM vectorise loops over many arrays without run-time overlap checks.
    Only for kernels whose array arguments never overlap (the filter owns them all).
    """

    def define_pipelines(self):
        self.state.flags.noalias = True
        return [DefaultPassBuilder.define_nopython_pipeline(self.state)]
'''

SOURCES = '''

@nb.njit(cache=True, nogil=True, error_model="numpy")
def row_sources(i, h, w, warp_on, geo, src):  # pragma: no cover - compiled
    """Spec step 1 for row i: src[j] = flat index of the previous cell that cell (i, j)
    comes from, by the float64 formula of reference.source_cells (no fastmath here, so
    both pick the same cells); cells from outside read the vacuous pad h * w + j.
    Integers pass through int32 (exact: the plane arrays stay far below 2^31 cells)
    because AVX2 converts between float64 and int32 vectors but not int64 ones: with
    int64 the loop is scalarised and costs ~1/4 of a 256 x 256 update."""
    ct, st, dx, dy, cell = geo[0], geo[1], geo[2], geo[3], geo[4]
    i0, j0 = h // 2, w // 2
    inv = 1.0 / cell
    x = (i0 - i) * cell
    for j in range(w):
        if warp_on:
            y = np.int32(j0 - j) * cell
            si = np.floor(i0 - (ct * x - st * y + dx) * inv + 0.5)
            sj = np.floor(j0 - (st * x + ct * y + dy) * inv + 0.5)
            inside = (si >= 0) & (si < h) & (sj >= 0) & (sj < w)
            src[j] = np.int32(si * w + sj) if inside else np.int32(h * w + j)
        else:
            src[j] = i * w + j
'''

DRIVER = '''

@nb.njit(cache=True, nogil=True, error_model="numpy")
def fused_update(m_prev, z_prev, sensor, gis, warp_on, geo, prm,
                 m_out, z_out, betp, first, stop):  # pragma: no cover - compiled
    w = sensor.shape[1]
    rb = np.empty((ROW_PLANES, w), np.float32)
    src = np.empty(w, np.int64)
    for i in range(first, stop):
        fused_row(i, m_prev, z_prev, sensor, gis, warp_on, geo, prm, m_out, z_out, betp, rb, src)
'''
"""The update of rows ``first .. stop - 1``; it releases the GIL, so bands of rows can
run in Python threads (rows are independent: any banding gives the same result)."""


INPLACE_DRIVER = '''

@nb.njit(cache=True, nogil=True, error_model="numpy")
def inplace_update(m, zeta, sensor, gis, warp_on, geo, prm, betp, hist, k_hist,
                   desc):  # pragma: no cover - compiled
    h, w = sensor.shape
    rb = np.empty((ROW_PLANES, w), np.float32)
    src = np.empty(w, np.int64)
    for r in range(h):
        i = h - 1 - r if desc else r
        inplace_row(i, m, zeta, sensor, gis, warp_on, geo, prm, betp, rb, src, hist, k_hist,
                    desc, m, zeta)
'''
"""The whole update in place, one thread: rows in ascending order (descending when
``desc``), with a ring of the ``k_hist`` last overwritten rows (``hist``:
``(ROW_PLANES, k_hist * W) float32``) for sources that lie behind the current row;
:func:`dstenv.dst._kernel.history_rows` sizes it from the motion."""
