"""Do parked cars' silhouettes flicker more in real scans than in simulated ones?

Issue 14: on KITTI the edge cells of static cars carry BetP(moving) 0.39 against 0.18
inside them; the simulator at KITTI's speed gives 0.14-0.17 on both. DST puts mass on
{M} where a cell that was free becomes occupied (dst-spec.md step 7), and a conflict
either way lowers zeta, which keeps that mass from being specialised to static. So
this script measures, on the visible cells labelled static at t, edge (a 4-neighbour
not static) and interior, the sensor state at t-1 moved into the frame of t by the
filter's own nearest-neighbour warp (:func:`dstenv.dst.reference.source_cells` with
:func:`dstenv.grid.relative_pose`) against the state at t::

    python docs/edge_flicker.py --kitti-root KITTI \\
        --drives 6 --out docs/edge-flicker.json [--lidar '{"hdl64": {...}}']
        [--world '{"map": {...}}'] [--icp] [--chained]

- ``occ_lost``: P(not occupied at t | occupied at t-1);
- ``occ_gained``: P(occupied at t | not occupied at t-1);
- ``free_to_occ``: P(occupied at t | free at t-1), the transition that puts mass on {M};
- ``occupied``: share of the cells occupied at t; ``free``: share free at t;
- ``betp_moving``: mean BetP(moving) at t.

KITTI: sequence 0003 converted with every scan kept (``stride 1, warmup 0``, the
benchmark's conversion), 256 x 256 cells, split at 21 m (the half side of the
simulated 128 x 128 grid). Sim: ``docs/ego_speed.py``'s ``sim_at_speed`` drives
(``dense``, no map, ``hdl64``, 128 x 128, parked density 0.3) in the ``fast``
variant, steps 10..119 of 12 s drives, by ego speed; ``--lidar`` merges overrides
into the ``lidar`` section (the before/after of a LIDAR effect), ``--world`` into the
``world`` section; ``--icp`` converts KITTI with the ICP scan-to-scan poses of
``docs/kitti_pose_check.py`` instead of OXTS'.

Label geometry (b): ``box_edges`` gives, for KITTI's static boxes in the camera view
and for the simulated parked cars, the share of edge and interior footprint cells
that hold no obstacle return (sensor state not occupied) and the share seen free.
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from ego_speed import FAST, STATIC, MOVING, _bin, _interior  # noqa: E402

from dstenv.dst.reference import source_cells  # noqa: E402
from dstenv.grid import GridSpec, relative_pose  # noqa: E402

_UNK, _FREE, _OCC = 0, 1, 2


#: sweeps of history per cell (the filter keeps 0.9 of its past per sweep: ~10 sweeps)
HISTORY = 10
#: move the history one sweep at a time by nearest cell, as the filter moves its state
#: (``--chained``), instead of straight from each earlier pose to t
CHAINED = False
#: [m] distance bins of the cells (the 128 x 128 grid reaches 21 m, 256 x 256 42 m)
DIST = (0.0, 10.0, 21.0, 30.0, 42.0, np.inf)
_BANDS = (*zip(DIST[:-1], DIST[1:]), (0.0, np.inf))


def _band(lo: float, hi: float) -> str:
    return "all" if (lo, hi) == (0.0, np.inf) else f"{lo:g}-{hi:g} m"


def warped(prev: np.ndarray, prev_pose: np.ndarray, pose: np.ndarray,
           spec: GridSpec) -> np.ndarray:
    """``(H, W) uint8`` an earlier sensor grid in the ego frame of t (nearest cell, the
    filter's warp); cells from outside the earlier grid are unknown."""
    si, sj, ok = source_cells(spec.shape, spec.cell_size, relative_pose(prev_pose, pose))
    out = np.zeros(spec.shape, np.uint8)
    out[ok] = prev[si[ok], sj[ok]]
    return out


class Tally:
    """Per key (distance bin, edge or interior), per static cell seen at t-1 or t: the
    state at t-1 and t, the sweeps of the last :data:`HISTORY` that saw it free, the
    occupied run ending at t-1, and BetP(moving) at t (NaN where not visible at t)."""

    def __init__(self) -> None:
        self.rows = defaultdict(list)

    def add(self, key: str, hist: np.ndarray, now: np.ndarray, betp: np.ndarray) -> None:
        """``hist``: ``(K, n)`` states at t-1, t-2, ...; ``now``, ``betp``: ``(n,)``."""
        k = hist.shape[0]
        occ = hist == _OCC
        run = np.where(occ.all(axis=0), k, np.argmin(occ, axis=0))
        self.rows[key].append(np.stack([hist[0], now, (hist == _FREE).sum(axis=0), run,
                                        np.where(now != _UNK, betp, np.nan)]))

    def table(self) -> dict:
        out = {}
        for key in sorted(self.rows):
            prev, now, n_free, run, betp = np.concatenate(self.rows[key], axis=1)
            vis = now != _UNK
            seen = vis | (prev != _UNK)
            po, no = prev == _OCC, now == _OCC
            ever = n_free > 0
            out[key] = {
                "cells_seen_t_or_t1": int(seen.sum()),
                "occ_lost": _r((po & ~no & seen).sum(), (po & seen).sum()),
                "occ_gained": _r((~po & no & seen).sum(), (~po & seen).sum()),
                "flip": _r((po != no)[seen].sum(), seen.sum()),
                "cells_visible_t": int(vis.sum()),
                "occupied_t": _r((no & vis).sum(), vis.sum()),
                "free_t": _r((now == _FREE).sum(), vis.sum()),
                "occupied_t1": _r((po & vis).sum(), vis.sum()),
                "free_t1": _r((prev == _FREE)[vis].sum(), vis.sum()),
                f"free_in_last_{HISTORY}": _r(ever[vis].sum(), vis.sum()),
                f"occupied_t_free_in_last_{HISTORY}": _r((ever & no).sum(), no.sum()),
                "mean_occ_run": _r(run[vis].sum(), vis.sum()),
                "betp_moving": _r(np.nansum(betp[vis]), vis.sum()),
                "betp_moving_if_free_before": _r(np.nansum(betp[vis & ever]), (vis & ever).sum()),
                "betp_moving_if_never_free": _r(np.nansum(betp[vis & ~ever]),
                                                (vis & ~ever).sum()),
            }
        return out


def _r(a: float, b: float) -> float | None:
    return round(float(a) / float(b), 3) if b else None


def _add_frame(tally: Tally, prefix: tuple, hist: np.ndarray, f, dist) -> None:
    """``hist``: ``(K, H, W)`` the earlier sensor grids of the drive in the frame of t,
    newest first; ``prefix``: the keys (source and speed) the frame counts under."""
    static = f.labels == STATIC
    inner = _interior(static)
    for part, m in (("edge", static & ~inner), ("interior", inner)):
        for lo, hi in _BANDS:
            sel = m & (dist >= lo) & (dist < hi) & ((f.sensor != _UNK) | (hist[0] != _UNK))
            if sel.any():
                for p in prefix:
                    tally.add(f"{p} {_band(lo, hi)} {part}", hist[:, sel], f.sensor[sel],
                              f.pignistic[MOVING][sel])


def _box(box: dict, prefix: str, f, dist) -> None:
    """Label geometry: every static footprint cell at t (visible or not), by state."""
    static = f.labels == STATIC
    inner = _interior(static)
    for part, m in (("edge", static & ~inner), ("interior", inner)):
        for lo, hi in _BANDS:
            sel = m & (dist >= lo) & (dist < hi)
            if sel.any():
                for p in prefix:
                    box[f"{p} {_band(lo, hi)} {part}"] += np.bincount(f.sensor[sel], minlength=3)


def _box_table(box: dict) -> dict:
    return {key: {"cells": int(n.sum()), "no_return": _r(n[_UNK] + n[_FREE], n.sum()),
                  "free": _r(n[_FREE], n.sum()), "unknown": _r(n[_UNK], n.sum())}
            for key, n in sorted(box.items())}


def _drive(frames, key_fn, spec: GridSpec, tally: Tally, box: dict, first: int = 1) -> None:
    """Feed one drive's frames (in order, consecutive sweeps) to the tallies."""
    x, y = spec.cell_centers()
    dist = np.hypot(x, y)
    past: list = []
    last = None
    chain: list = []  # CHAINED: the grids moved one sweep at a time, as the filter's state
    for t, f in enumerate(frames):
        if CHAINED and last is not None:
            step = relative_pose(last.ego_pose, f.ego_pose)
            si, sj, ok = source_cells(spec.shape, spec.cell_size, step)
            for g in chain:
                g[ok], g[~ok] = g[si[ok], sj[ok]].copy(), _UNK
        if t >= first and past:
            key = key_fn(f)
            hist = (np.stack(chain) if CHAINED else
                    np.stack([warped(p.sensor, p.ego_pose, f.ego_pose, spec) for p in past]))
            _add_frame(tally, key, hist, f, dist)
            _box(box, key, f, dist)
        past = [f, *past][:HISTORY]
        chain = [f.sensor.copy(), *chain][:HISTORY]
        last = f


def kitti(root: Path, sequence: str, icp: bool = False) -> dict:
    from dstenv.kitti.sequence import KittiSequence, convert_sequence

    seq = KittiSequence(root, sequence)
    tally, box = Tally(), defaultdict(lambda: np.zeros(3, np.int64))
    spec = GridSpec(256, 256, 0.33)
    if icp:  # the scans registered to each other (docs/kitti_pose_check.py)
        from kitti_pose_check import use_icp_poses

        use_icp_poses(seq)
    frames = list(convert_sequence(seq, {"stride": 1, "warmup": 0}))
    assert [f.step for f in frames] == list(range(len(frames))), "a skipped scan"
    _drive(frames, lambda f: ("kitti",), spec, tally, box)
    return {"flicker": tally.table(), "box_edges": _box_table(box)}


def sim(drives: int, lidar: dict | None, size: int = 128, world: dict | None = None) -> dict:
    from dstenv.config import merge_config
    from dstenv.data.sampling import scenario_config
    from dstenv.pipeline import Pipeline

    over = {"grid": {"height": size, "width": size}, "lidar": {"model": "hdl64"},
            "gis": {"no_map_prob": 1.0}, "world": {"traffic": {"parked_density": 0.3}}}
    if lidar:
        over = _deep(over, {"lidar": lidar})
    if world:
        over = _deep(over, {"world": world})
    pipe = Pipeline(merge_config(scenario_config("dense", over), FAST, "fast"))
    tally, box = Tally(), defaultdict(lambda: np.zeros(3, np.int64))
    points: list[int] = []

    def frames():
        yield pipe.reset(seed)
        for t in range(1, 120):
            f = pipe.step(None)
            f.extras["speed"] = pipe.world.ego_speed
            if t % 10 == 0:
                points.append(len(pipe.sweep))
            yield f

    for seed in range(drives):
        _drive(frames(), _sim_keys, pipe.spec, tally, box, first=10)
    return {"flicker": tally.table(), "box_edges": _box_table(box),
            "points_per_scan_median": int(np.median(points)) if points else None}


def _sim_keys(f) -> tuple:
    v = f.extras["speed"]
    return (f"sim {_bin(v)} m/s",) + (("sim 9-15 m/s",) if v >= 9.0 else ())


def _deep(base: dict, over: dict) -> dict:
    out = dict(base)
    for k, v in over.items():
        out[k] = _deep(out.get(k, {}), v) if isinstance(v, dict) else v
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--kitti-root", help="omit to measure the simulator only")
    ap.add_argument("--sequence", default="0003")
    ap.add_argument("--drives", type=int, default=6)
    ap.add_argument("--grid", type=int, default=128, help="simulated grid side [cells]")
    ap.add_argument("--lidar", default="", help="JSON overrides of the lidar section")
    ap.add_argument("--world", default="", help="JSON overrides of the world section")
    ap.add_argument("--out", required=True)
    ap.add_argument("--icp", action="store_true",
                    help="KITTI with ICP scan-to-scan poses instead of OXTS")
    ap.add_argument("--chained", action="store_true", help="history warped sweep by sweep")
    ap.add_argument("--autopilot", type=float, default=0.0,
                    help="[m/s] fast variant's autopilot and start speed (0: FAST's)")
    args = ap.parse_args()
    global CHAINED
    CHAINED = args.chained
    if args.autopilot:
        FAST["world"]["ego"].update(autopilot_speed=args.autopilot, initial_speed=args.autopilot)
    res = {"command": "python docs/edge_flicker.py " + shlex.join(sys.argv[1:])}
    if args.kitti_root:
        res["kitti"] = kitti(Path(args.kitti_root), args.sequence, args.icp)
    if args.drives:
        res["sim"] = sim(args.drives, json.loads(args.lidar) if args.lidar else None,
                         args.grid, json.loads(args.world) if args.world else None)
    from dstenv.io import atomic_write_text

    atomic_write_text(Path(args.out), json.dumps(res, indent=1) + "\n")
    print(json.dumps(res, indent=1))


if __name__ == "__main__":
    main()
