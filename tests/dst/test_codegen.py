"""The committed kernel is what the generator writes, and LLVM vectorises it."""

import re

import numba
import numpy as np

from dstenv.dst import DSTParams, _codegen, _fused
from dstenv.dst._kernel import REACHABLE, kernel_params, plane_grid


def test_generated_kernel_is_up_to_date():
    assert _codegen.TARGET.read_text() == _codegen.render(), (
        "dstenv/dst/_fused.py is stale: run `python -m dstenv.dst._codegen --write`"
    )


def test_cli_needs_an_explicit_write(capsys):
    import pytest

    with pytest.raises(SystemExit):  # no flag: usage, nothing written
        _codegen.main([])
    assert "--write" in capsys.readouterr().err
    assert _codegen.main(["--check"]) == 0
    assert "current" in capsys.readouterr().out


def test_reachable_sets():
    assert list(REACHABLE) == [1, 2, 3, 4, 8, 9, 10, 12, 15, 16, 24, 25, 26, 28, 31]
    # N, W, F, I, {S,M}, {N,S,M}, {W,S,M}, O, Omega: sensor focal x map focal, non-empty
    assert _codegen.SM_SETS == [1, 2, 3, 4, 24, 25, 26, 28, 31]


def test_row_kernel_is_vectorised():
    """The per-cell arithmetic compiles to vector instructions (on numba 0.68 it does
    not without the noalias pipeline, and the update then runs ~2.5x slower)."""
    h, w = 3, 40
    masses = plane_grid(32, (h, w))
    masses[31] = 1.0
    args = (
        1, masses, plane_grid(1, (h, w))[0],
        np.ones((h, w), np.uint8), np.full((h, w), 2, np.uint8),
        True, np.array([1.0, 0.0, 0.33, 0.0, 0.33]), kernel_params(DSTParams()),
        plane_grid(32, (h, w)), plane_grid(1, (h, w))[0], plane_grid(5, (h, w)),
        np.empty((_fused.ROW_PLANES, w), np.float32), np.empty(w, np.int64),
    )
    kernel = _fused.fused_row  # compiled afresh (inspection needs it), with the same options
    fresh = numba.jit(pipeline_class=_fused.NoAliasCompiler, **kernel.targetoptions)(kernel.py_func)
    fresh(*args)
    assert re.search(r"fadd[^\n]*<\d+ x float>", next(iter(fresh.inspect_llvm().values())))


def test_in_place_row_kernel_is_vectorised():
    h, w = 3, 40
    masses, zeta = plane_grid(32, (h, w)), plane_grid(1, (h, w))[0]
    masses[31] = 1.0
    args = (
        1, masses, zeta, np.ones((h, w), np.uint8), np.full((h, w), 2, np.uint8),
        True, np.array([1.0, 0.0, 0.33, 0.0, 0.33]), kernel_params(DSTParams()),
        plane_grid(5, (h, w)), np.empty((_fused.ROW_PLANES, w), np.float32),
        np.empty(w, np.int64), np.empty((_fused.ROW_PLANES, w), np.float32), 1, False,
        masses, zeta,
    )
    kernel = _fused.inplace_row
    fresh = numba.jit(pipeline_class=_fused.NoAliasCompiler, **kernel.targetoptions)(kernel.py_func)
    fresh(*args)
    assert re.search(r"fadd[^\n]*<\d+ x float>", next(iter(fresh.inspect_llvm().values())))
