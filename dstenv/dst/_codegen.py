"""Writes ``_fused.py``: the perception-grid update as one SIMD-friendly row kernel.

Only 15 subsets can ever carry mass in a filter state (:data:`REACHABLE`: the
intersection closure of the sensor-and-map focal sets, their specialisations and
{M}), so once a cell's inputs and accumulator are known the update is a fixed
linear map of 15 numbers. This module derives that map from the bit layout and
writes it as straight-line scalar code that LLVM vectorises across the cells of a
row (16 cells per AVX-512 register). What makes it vectorisable, and why:

* No per-cell branches. m_sm = dempster(sensor, map) is evaluated per cell from the
  two codes with a few selects and products (instead of a branch per (sensor, map)
  case), and the temporal combination sums over all 9 sets that m_sm can ever have,
  each weighted by its per-cell mass (0 where absent).
* Contiguous loads only. The ego-motion warp (nearest neighbour) is a per-row
  pre-pass: it computes each cell's source; a row whose sources are consecutive
  (no turn) is read in place, any other row is first copied run by run into a small
  row buffer, so the arithmetic loop never gathers (gathers are slow on AMD Zen and
  LLVM declines to emit them there).
* ``noalias`` arguments (:data:`NOALIAS_COMPILER`). numba does not tell LLVM that
  the ~40 array streams of the loop never overlap; proving it at run time needs more
  pointer checks than LLVM allows, and then nothing is vectorised (2.5x slower).
* In place (``inplace_row``, the one-thread default): the row buffer is filled from
  the state, or from a ring of the rows this update already overwrote, so the grid
  needs no second buffer (each cache line is read and written back once instead of
  read from one buffer and allocated in another: ~25 % faster at 256 x 256, where
  the update is bound by memory). ``fused_row`` (two buffers) serves bands of rows
  in threads.
* One loop over the row's cells, not stages. On AVX2 (16 ymm registers) the loop
  spills ~120 vectors per 8 cells, but staging it through an L1 block scratch
  (steps 2-6, then the combination in two or three groups of outputs, then BetP;
  spills down to ~70) measured 0-13 % slower on an AVX2 EPYC (Zen 3), and changed
  last bits (other FMA contractions): the spills are not what bounds it there.
* float32 arithmetic with fused multiply-add (``fastmath={'contract'}`` only: no
  reassociation, so results are deterministic); agreement with the float64
  reference stays below 1e-6.

The numbers (confidences, alpha, ...) stay run-time arguments (:data:`PRM`).
Regenerate after changing the frame or this file: ``python -m dstenv.dst._codegen``
(a test checks that the committed file matches).
"""

from __future__ import annotations

from pathlib import Path

from dstenv.dst.frame import FREE, M, NUM_CLASSES, OCCUPIED, OMEGA, subset_name
from dstenv.dst._templates import DRIVER, INPLACE_DRIVER, NOALIAS_COMPILER, SOURCES
from dstenv.dst.inputs import MAP_SETS, SENSOR_SETS

TARGET = Path(__file__).with_name("_fused.py")


def _closure(seed: set[int]) -> list[int]:
    sets = set(seed) | {M, OMEGA}
    sets |= {a & ~M for a in sets if a & M and a != M}
    while True:
        new = {a & b for a in sets for b in sets if a & b} - sets
        if not new:
            return sorted(sets)
        sets |= new


def _focal(table: dict[int, int]) -> list[int]:
    """Focal sets of one input's evidence: the sets its codes support, and Omega."""
    return sorted(set(table.values()) | {OMEGA})


SENSOR_FOCAL = _focal(SENSOR_SETS)
MAP_FOCAL = _focal(MAP_SETS)
SM_SETS = sorted({a & b for a in SENSOR_FOCAL for b in MAP_FOCAL if a & b})
"""The sets m_sm = dempster(sensor, map) can put mass on, over all inputs."""
REACHABLE = _closure(set(SM_SETS))
POS = {a: k for k, a in enumerate(REACHABLE)}
PRM = ("alpha", "keep", "dinc", "ddec", "g_occ", "g_conf", "cs", "ncs", "cm", "ncm")
"""Order of the kernel's float32 parameter vector (keep = 1 - alpha, ncs = 1 - cs, ...)."""

def route(b: int, c: int) -> int:
    """Where the product m_past(B) m_sm(C) goes (spec step 7)."""
    if b & c:
        return b & c
    if b & ~FREE == 0 and c & ~OCCUPIED == 0:
        return M
    return OMEGA


def _sum(names: list[str]) -> str:
    return " + ".join(names) if names else "zero"


def _evidence(var: str, code: str, table: dict[int, int], conf: str, nconf: str) -> list[str]:
    """Per-cell masses ``<var><set>`` of one input's focal sets (spec "Inputs per cell")."""
    lines = []
    for a in sorted(set(table.values()) - {OMEGA}):
        hit = " | ".join(f"({code} == {c})" for c, s in sorted(table.items()) if s == a)
        lines.append(f"{var}{a} = {conf} if {hit} else zero  # {subset_name(a)}")
    vacuous = " | ".join(f"({code} == {c})" for c, s in sorted(table.items()) if s == OMEGA)
    lines.append(f"{var}{OMEGA} = one if {vacuous} else {nconf}  # Omega")
    return lines


def _sensor_map() -> list[str]:
    """Spec step 2 per cell: ``w<C>`` = m_sm(C) for every C in SM_SETS."""
    lines = _evidence("ms", "sv", SENSOR_SETS, "cs", "ncs")
    lines += _evidence("mg", "gv", MAP_SETS, "cm", "ncm")
    products: dict[int, list[str]] = {}
    for a in SENSOR_FOCAL:
        for b in MAP_FOCAL:
            products.setdefault(a & b, []).append(f"ms{a} * mg{b}")
    lines += [
        f"k = {_sum(products.pop(0, []))}  # conflict K",
        "total = k >= one  # total conflict: m_sm is vacuous, as in rules.dempster",
        "norm = zero if total else one / (one - k)",
    ]
    for c in SM_SETS:
        w = f"({_sum(products[c])}) * norm"
        w = f"one if total else {w}" if c == OMEGA else w
        lines.append(f"w{c} = {w}  # m_sm({subset_name(c)})")
    return lines


def _combination() -> list[str]:
    """Spec step 7 over all of SM_SETS: ``o<d>`` = sum_C w<C> * (sum of p<k> routed to d)."""
    terms: dict[int, list[str]] = {}
    for c in SM_SETS:
        groups: dict[int, list[str]] = {}
        for k, b in enumerate(REACHABLE):
            groups.setdefault(POS[route(b, c)], []).append(f"p{k}")
        for d, srcs in groups.items():
            group = f"({_sum(srcs)})" if len(srcs) > 1 else srcs[0]
            terms.setdefault(d, []).append(f"w{c} * {group}")
    return [f"o{d} = {_sum(terms[d])}" for d in range(len(REACHABLE))]


def _gather(pad: str, masses: str, zeta: str) -> list[str]:
    """Lines (indented by ``pad``) that copy the reachable masses and zeta of source
    cell ``s`` of the state arrays named ``masses`` / ``zeta`` into the row buffer's
    column ``u``."""
    nr = len(REACHABLE)
    return ([f"{pad}rb[{k}, u] = {masses}[{a}, s]" for k, a in enumerate(REACHABLE)]
            + [f"{pad}rb[{nr}, u] = {zeta}[s]"])


def _row() -> list[str]:
    """Steps 1-8 for row i: sources, then the cell loop over the previous grid itself
    when the whole row comes from one run of consecutive cells (no turn: ~25% faster),
    else over a row buffer filled run by run (the cell loop must read contiguously)."""
    nr = len(REACHABLE)
    lines = [
        "    row_sources(i, h, w, warp_on, geo, src)",
        "    row = i * w",
        "    single = True",
        "    for j in range(1, w):",
        "        if src[j] != src[j - 1] + 1:",
        "            single = False",
        "            break",
        "    if single:",
        "        off = src[0]",
        "        for t in range(w):",
        "            s, u, at = np.uint64(off + t), np.uint64(t), np.uint64(row + t)",
    ]
    lines += _cell("    ", [f"m_prev[{a}, s]" for a in REACHABLE] + ["z_prev[s]"])
    lines += [
        "        return",
        "    # copy each run of consecutive sources with a plain loop; unsigned indices",
        "    # skip numba's negative-index wraparound, which would defeat vectorisation",
        "    a = 0",
        "    for j in range(1, w + 1):",
        "        if j < w and src[j] == src[j - 1] + 1:",
        "            continue",
        "        off = src[a] - a",
        "        for t in range(a, j):",
        "            s, u = np.uint64(off + t), np.uint64(t)",
    ]
    lines += _gather("            ", "m_prev", "z_prev")
    lines += [
        "        a = j",
        "    for t in range(w):",
        "        u, at = np.uint64(t), np.uint64(row + t)",
    ]
    return lines + _cell("", [f"rb[{k}, u]" for k in range(nr + 1)])


def _row_inplace() -> list[str]:
    """Steps 1-8 for row i of a grid updated in place (:data:`INPLACE_DRIVER`). A row
    whose sources are one run in a row not yet visited is read in place (as in
    :func:`_row`); otherwise each run of consecutive sources is copied into the row
    buffer from the state, or, for a row this update has already overwritten, from the
    history ring ``hist`` (the original rows ``i - k_hist .. i - 1``, or
    ``i + 1 .. i + k_hist`` when ``desc``). Row i is saved to the ring (when there is
    one) before it is overwritten."""
    nr = len(REACHABLE)
    save = [  # row i into the ring, before it is overwritten
        "if k_hist > 0:",
        "    base = (i % k_hist) * w",
        "    for t in range(w):",
        "        s, at = np.uint64(base + t), np.uint64(row + t)",
    ]
    save += [f"        hist[{k}, s] = m[{a}, at]" for k, a in enumerate(REACHABLE)]
    save += [f"        hist[{nr}, s] = zeta[at]"]
    lines = [
        "    row_sources(i, h, w, warp_on, geo, src)",
        "    row = i * w",
        "    single = True",
        "    for j in range(1, w):",
        "        if src[j] != src[j - 1] + 1:",
        "            single = False",
        "            break",
        "    # one run from a row not yet overwritten and not row i itself: read it through",
        "    # m_src (the same array; the rows touched are disjoint, as noalias requires)",
        "    if single and ((src[w - 1] // w < i) if desc else (src[0] // w > i)):",
        *("        " + line for line in save),
        "        off = src[0]",
        "        for t in range(w):",
        "            s, u, at = np.uint64(off + t), np.uint64(t), np.uint64(row + t)",
    ]
    lines += _cell("    ", [f"m_src[{a}, s]" for a in REACHABLE] + ["z_src[s]"], "m", "zeta")
    lines += [
        "        return",
        "    a = 0",
        "    for j in range(1, w + 1):",
        "        if j < w and src[j] == src[j - 1] + 1:",
        "            continue",
        "        while a < j:  # the run, split where it crosses into the next row",
        "            srow = src[a] // w",
        "            e = min(j, a + (srow + 1) * w - src[a])",
        "            off = src[a] - a",
        "            lag = (srow - i) if desc else (i - srow)",
        "            if srow < h and lag > 0:",
        "                if lag > k_hist:",
        "                    raise RuntimeError('inplace_update: history ring too short')",
        "                off = off + ((srow % k_hist) - srow) * w",
        "                for t in range(a, e):",
        "                    s, u = np.uint64(off + t), np.uint64(t)",
    ]
    lines += [f"                    rb[{k}, u] = hist[{k}, s]" for k in range(nr + 1)]
    lines += [
        "            else:",
        "                for t in range(a, e):",
        "                    s, u = np.uint64(off + t), np.uint64(t)",
    ]
    lines += _gather("                    ", "m", "zeta")
    lines += [
        "            a = e",
        *("    " + line for line in save),
        "    for t in range(w):",
        "        u, at = np.uint64(t), np.uint64(row + t)",
    ]
    return lines + _cell("", [f"rb[{k}, u]" for k in range(nr + 1)], "m", "zeta")


def _cell(indent: str, past: list[str], m_out: str = "m_out", z_out: str = "z_out") -> list[str]:
    """Steps 2-8 and BetP for cell ``at`` (column ``u``) of row i, whose past masses
    and zeta are the expressions ``past`` (in REACHABLE order, then zeta); the new
    masses and zeta go to the arrays named ``m_out`` and ``z_out``."""
    nr = len(REACHABLE)
    free = [f"p{k}" for k, a in enumerate(REACHABLE) if a & ~FREE == 0]
    occ = [f"p{k}" for k, a in enumerate(REACHABLE) if a & ~OCCUPIED == 0]
    body = [f"p{k} = {past[k]}  # {subset_name(a)}" for k, a in enumerate(REACHABLE)]
    body += [f"z = {past[nr]}", "sv, gv = sensor[i, u], gis[i, u]", "# 2. sensor and map"]
    body += _sensor_map()
    body += [
        "# 3. conflicts, 4. accumulator",
        f"mf = {_sum(free)}",
        f"mo = {_sum(occ)}",
        "sm_free = " + _sum([f"w{c}" for c in SM_SETS if c & ~FREE == 0]),
        "sm_occ = " + _sum([f"w{c}" for c in SM_SETS if c & ~OCCUPIED == 0]),
        "conflict = mf * sm_occ + mo * sm_free",
        "z_dec = max(zero, z - ddec)",
        "z_inc = min(one, z + dinc)",
        "z = z_dec if conflict > g_conf else (z_inc if mo >= g_occ else z)",
        f"{z_out}[at] = z",
        "# 5. specialisation (A -> A minus {M}), 6. discounting",
    ]
    for k, a in enumerate(REACHABLE):
        if a & M and a != M:
            d = POS[a & ~M]
            body += [f"t{k} = z * p{k}", f"p{d} = p{d} + t{k}", f"p{k} = p{k} - t{k}"]
    body += [f"p{k} = p{k} * keep" for k in range(nr)]
    body += [f"p{nr - 1} = p{nr - 1} + alpha", "# 7. modified conjunctive combination"]
    body += _combination()
    body += [f"{m_out}[{a}, at] = o{d}" for d, a in enumerate(REACHABLE)]
    body.append("# BetP, unless betp is None (numba compiles that case without it)")
    body.append("if betp is not None:")
    body += [f"    {line}" for line in _betp()]
    return [f"        {indent}{line}" for line in body]


def _betp() -> list[str]:
    """BetP of cell ``at`` from its masses ``o<d>`` (REACHABLE order) into ``betp``: each
    set's share 1/|A| once, then the sum per class. One text for the update and for
    :data:`BETP_DRIVER`, so both round the same way."""
    nr = len(REACHABLE)
    card = [bin(a).count("1") for a in REACHABLE]
    body = [f"q{d} = o{d} * r{card[d]}" for d in range(nr) if card[d] > 1]
    for x in range(NUM_CLASSES):
        parts = [f"o{d}" if card[d] == 1 else f"q{d}"
                 for d, a in enumerate(REACHABLE) if a >> x & 1]
        body.append(f"betp[{x}, at] = {_sum(parts)}")
    return body



def _kernel_head(signature: list[str], ratios: range) -> list[str]:
    """Decorator, signature (its last line marked compiled) and the shared preamble of a
    generated row kernel: grid shape, parameters, constants, reciprocal ratios."""
    return [
        "",
        "",
        "@nb.njit(cache=True, nogil=True, error_model='numpy', fastmath={'contract'},",
        "         pipeline_class=NoAliasCompiler)",
        *signature[:-1],
        signature[-1] + "  # pragma: no cover - compiled",
        "    h, w = sensor.shape",
        "    " + ", ".join(PRM) + " = " + ", ".join(f"prm[{k}]" for k in range(len(PRM))),
        "    zero, one = np.float32(0.0), np.float32(1.0)",
        "    " + ", ".join(f"r{c}" for c in ratios) + " = "
        + ", ".join(f"np.float32({1.0 / c!r})" for c in ratios),
    ]

def render() -> str:
    """Source text of ``_fused.py``."""
    ratios = range(2, NUM_CLASSES + 1)
    lines = [
        '"""GENERATED by dstenv/dst/_codegen.py from the bit layout: do not edit."""',
        "",
        "import numba as nb",
        "import numpy as np",
        "from numba.core.compiler import CompilerBase, DefaultPassBuilder",
        "",
        f"REACHABLE = np.array({REACHABLE}, dtype=np.int64)",
        f"SM_SETS = {SM_SETS}",
        f"PRM = {PRM!r}",
        "ROW_PLANES = REACHABLE.size + 1  # row buffer: the past masses, then zeta",
    ]
    for block in (NOALIAS_COMPILER, SOURCES):
        lines += ["", "", *block.strip("\n").splitlines()]
    lines += _kernel_head(["def fused_row(i, m_prev, z_prev, sensor, gis, warp_on, geo, prm,",
                           "              m_out, z_out, betp, rb, src):"], ratios)
    lines += _row()
    lines += ["", "", *DRIVER.strip("\n").splitlines()]
    lines += _kernel_head(
        ["def inplace_row(i, m, zeta, sensor, gis, warp_on, geo, prm, betp, rb, src,",
         "                hist, k_hist, desc, m_src, z_src):"], ratios)
    lines += _row_inplace()
    lines += ["", "", *INPLACE_DRIVER.strip("\n").splitlines()]
    lines += [
        "",
        "",
        "@nb.njit(cache=True, nogil=True, error_model='numpy', fastmath={'contract'},",
        "         pipeline_class=NoAliasCompiler)",
        "def pignistic_planes(m, betp, n):  # pragma: no cover - compiled",
        '    """BetP of cells 0 .. n - 1 of the state ``m`` into ``betp`` (the update\'s',
        '    arithmetic: the same bits as an update that writes BetP)."""',
        "    " + ", ".join(f"r{c}" for c in ratios) + " = "
        + ", ".join(f"np.float32({1.0 / c!r})" for c in ratios),
        "    for t in range(n):",
        "        at = np.uint64(t)",
    ]
    lines += [f"        o{d} = m[{a}, at]" for d, a in enumerate(REACHABLE)]
    lines += [f"        {line}" for line in _betp()]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    """``python -m dstenv.dst._codegen --write | --check``: rewrite the package's
    ``_fused.py`` from :func:`render`, or only say whether it is current (exit 1 if not)."""
    import argparse

    ap = argparse.ArgumentParser(prog="python -m dstenv.dst._codegen",
                                 description=f"Generate {TARGET.name}, the fused DST kernel.")
    what = ap.add_mutually_exclusive_group(required=True)
    what.add_argument("--write", action="store_true", help=f"rewrite {TARGET}")
    what.add_argument("--check", action="store_true", help="only compare; exit 1 if stale")
    args = ap.parse_args(argv)
    current = TARGET.exists() and TARGET.read_text() == render()
    if args.check:
        print(f"{TARGET}: {'current' if current else 'stale: run with --write'}")
        return 0 if current else 1
    if not current:
        TARGET.write_text(render())
    print(f"{'wrote' if not current else 'already current:'} {TARGET}")
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
