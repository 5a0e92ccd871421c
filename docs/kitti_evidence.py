"""DST moving evidence on simulated and on real KITTI grids, measured the same way (issue 14).

A network trained on simulated grids learns what strong moving evidence usually is
in the simulator. This script measures, on the real KITTI sample (no map) and on
simulated no-map drives of the benchmark's world (``dense``, 3-D LIDAR, 128 x 128
cells of 0.33 m, as ``dstenv benchmark --preset cpu``), the figures that tell one
world from the other::

    python docs/kitti_evidence.py --kitti-root KITTI \\
        --drives 120 --out docs/kitti-evidence.json

Region: KITTI labels only its left camera's field of view, and DontCare regions are
unknown, so the KITTI figures use visible cells inside the camera view outside
DontCare; the simulated ones use the same 81 deg forward view (``camera_mask``), and
``all`` repeats some of them over the whole grid. On KITTI, occupied cells without a
box keep the ignore label (walls, poles, trees): here they count as ``other`` (not
moving), the simulator's ``non_navigable`` (clutter) and ``building`` cells alike.

Figures (``strong``: visible, BetP(moving) at t > 0.45):

- ``strong``: share of strong cells by label (moving / static / navigable / other)
  and by sensor state, and strong cells per frame;
- ``false_alarms``: strong cells not labelled moving per occupied visible cell, by
  distance band, and the recall of visible moving cells (strong / visible moving);
- ``moving_ring``: sensor states in the ring 1-3 m around each labelled moving object
  that has a visible cell, on its near side (closer to the ego than the object's
  centroid) and far side; ``edge_share``: objects whose ring is less than half free;
- ``moving_objects_per_frame``: moving objects (KITTI boxes, simulated agents) by
  kind whose centre lies in the grid, and in the region;
- ``occupied``: unknown / free / occupied share of the sensor grid by distance.

The KITTI frames are the 40 scans of sequence 0003 fused at 10 Hz from scan 0; frames
10-39 are measured (the simulated frames likewise come after a 1 s warm-up: steps
10, 20, ..., 50 of 6 s drives, as the benchmark keeps them).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
from scipy.ndimage import binary_dilation, distance_transform_edt, label

from dstenv.dst import CLASSES, SensorState
from dstenv.grid import GridSpec

MOVING, STATIC, NAV = (CLASSES.index(c) for c in ("moving", "static", "navigable"))
STRONG = 0.45  # BetP(moving) above which a cell "reads moving" (kitti_transfer.py's threshold)
BANDS = ((0.0, 10.0), (10.0, 20.0), (20.0, 99.0))  # [m] distance from the ego
RING = (1.0, 3.0)  # [m] ring around labelled moving objects
GRID, CELL = 128, 0.33  # the cpu preset's grid
SIM_FOV = 81.0  # [deg] the paper protocol's camera field of view (KITTI's left camera)
CATS = ("moving", "static", "navigable", "other")
STATES = ("unknown", "free", "occupied")


class Tally:
    """Counts of one data source, summed over frames."""

    def __init__(self, spec: GridSpec) -> None:
        x, y = spec.cell_centers()
        self.rng = np.hypot(x, y)
        self.band = np.digitize(self.rng, [b[1] for b in BANDS[:-1]])
        self.cell = spec.cell_size
        self.frames = 0
        self.strong_cat = np.zeros(len(CATS))
        self.strong_state = np.zeros(3)
        self.fa = np.zeros(len(BANDS))
        self.occ = np.zeros(len(BANDS))
        self.mov_vis = np.zeros(len(BANDS))
        self.mov_lab = np.zeros(len(BANDS))
        self.mov_hit = np.zeros(len(BANDS))
        self.mov_betp = []
        self.halo = 0  # strong cells not labelled moving that touch a moving cell
        self.face = np.zeros(2)  # occupied visible cells on or touching moving ones: moving, not
        self.ring = np.zeros((2, 3))  # near / far side x sensor state
        self.objects = 0
        self.edge = 0
        self.obj_range: list[float] = []
        self.grid_states = np.zeros((len(BANDS), 3))
        self.grid_cells = np.zeros(len(BANDS))
        self.fov_states = np.zeros((len(BANDS), 3))
        self.spec = spec
        self.agents: dict[str, np.ndarray] = {}  # kind -> moving ones in the grid, in region

    def add_agents(self, kind: np.ndarray, xy: np.ndarray, moving: np.ndarray,
                   region: np.ndarray) -> None:
        """Moving objects of one frame: ``kind (N,)`` names, ``xy (N, 2)`` ego-frame
        centres [m], ``moving (N,) bool``; counted when their centre cell is in the grid,
        and in ``region``."""
        i, j = self.spec.to_cell(xy[:, 0], xy[:, 1])
        inside = self.spec.inside(i, j) & moving
        ins = np.zeros(len(kind), bool)
        ins[inside] = region[i[inside], j[inside]]
        for k in set(kind.tolist()):
            c = self.agents.setdefault(k, np.zeros(2))
            c += (np.count_nonzero(inside & (kind == k)), np.count_nonzero(ins & (kind == k)))

    def add(self, betp_moving: np.ndarray, labels: np.ndarray, sensor: np.ndarray,
            region: np.ndarray) -> None:
        """One frame: ``(H, W)`` BetP(moving) float, labels uint8, sensor uint8, region bool
        (cells whose label is meaningful: camera view, not DontCare)."""
        self.frames += 1
        vis = sensor != SensorState.UNKNOWN
        cat = np.full(labels.shape, 3, np.int64)  # other
        cat[labels == MOVING], cat[labels == STATIC], cat[labels == NAV] = 0, 1, 2
        strong = vis & region & (betp_moving > STRONG)
        self.strong_cat += np.bincount(cat[strong], minlength=4)
        self.strong_state += np.bincount(sensor[strong], minlength=3)
        occ = vis & region & (sensor == SensorState.OCCUPIED)
        mov = labels == MOVING
        for b in range(len(BANDS)):
            inb = self.band == b
            self.fa[b] += np.count_nonzero(strong & inb & ~mov)
            self.occ[b] += np.count_nonzero(occ & inb)
            self.mov_vis[b] += np.count_nonzero(vis & region & mov & inb)
            self.mov_lab[b] += np.count_nonzero(region & mov & inb)
            self.mov_hit[b] += np.count_nonzero(strong & mov & inb)
            self.grid_states[b] += np.bincount(sensor[inb], minlength=3)
            self.grid_cells[b] += np.count_nonzero(inb)
            self.fov_states[b] += np.bincount(sensor[inb & region], minlength=3)
        self.mov_betp.append(betp_moving[vis & region & mov])
        touch = binary_dilation(mov, np.ones((3, 3), bool))
        self.halo += np.count_nonzero(strong & touch & ~mov)
        self.face += (np.count_nonzero(occ & mov), np.count_nonzero(occ & touch & ~mov))
        self._ring(mov & region, vis, sensor, region)

    def _ring(self, mov: np.ndarray, vis: np.ndarray, sensor: np.ndarray,
              region: np.ndarray) -> None:
        comp, n = label(mov, structure=np.ones((3, 3)))
        if n == 0:
            return
        d, (ii, jj) = distance_transform_edt(~mov, return_indices=True)
        d *= self.cell
        owner = comp[ii, jj]
        ring = (d >= RING[0]) & (d <= RING[1]) & region
        for k in range(1, n + 1):
            body = comp == k
            if not (body & vis).any():
                continue
            rc = float(self.rng[body].mean())
            cells = ring & (owner == k)
            near = cells & (self.rng < rc)
            far = cells & ~near
            self.ring[0] += np.bincount(sensor[near], minlength=3)
            self.ring[1] += np.bincount(sensor[far], minlength=3)
            st = np.bincount(sensor[cells], minlength=3)
            self.objects += 1
            self.edge += int(st[SensorState.FREE] < 0.5 * max(1, st.sum()))
            self.obj_range.append(rc)

    def summary(self) -> dict:
        def r(v):
            return [round(float(a), 4) for a in v] if np.ndim(v) else round(float(v), 4)

        def shares(c):
            c = np.asarray(c, float)
            return dict(zip(STATES, r(c / max(1.0, c.sum()))))

        s = self.strong_cat.sum()
        betp = np.concatenate(self.mov_betp) if self.mov_betp else np.zeros(0)
        names = [f"{a:g}-{b:g} m" if b < 99 else f">= {a:g} m" for a, b in BANDS]
        ring_all = self.ring.sum(0)
        return {
            "frames": self.frames,
            "strong": {
                "cells_per_frame": r(s / max(1, self.frames)),
                "label_share": dict(zip(CATS, r(self.strong_cat / max(1.0, s)))),
                "sensor_share": shares(self.strong_state),
                "touching_moving_share": r(self.halo / max(1.0, s)),
            },
            "false_alarms": {
                name: {"per_occupied_visible_cell": r(self.fa[b] / max(1.0, self.occ[b])),
                       "false_alarm_cells_per_frame": r(self.fa[b] / max(1, self.frames)),
                       "occupied_visible_per_frame": r(self.occ[b] / max(1, self.frames)),
                       "moving_labelled_per_frame": r(self.mov_lab[b] / max(1, self.frames)),
                       "moving_visible_per_frame": r(self.mov_vis[b] / max(1, self.frames)),
                       "moving_recall": r(self.mov_hit[b] / max(1.0, self.mov_vis[b]))}
                for b, name in enumerate(names)
            },
            "moving_visible": {
                "cells": int(betp.size),
                "mean_betp_moving": r(betp.mean()) if betp.size else None,
                "share_strong": r((betp > STRONG).mean()) if betp.size else None,
                "occupied_face_labelled_moving": r(self.face[0] / max(1.0, self.face.sum())),
            },
            "moving_ring": {
                "objects": self.objects,
                "median_range_m": r(np.median(self.obj_range)) if self.obj_range else None,
                "ring": shares(ring_all),
                "near_side": shares(self.ring[0]),
                "far_side": shares(self.ring[1]),
                "edge_share": r(self.edge / max(1, self.objects)),
            },
            "moving_objects_per_frame": {
                k: {"grid": r(v[0] / max(1, self.frames)), "region": r(v[1] / max(1, self.frames))}
                for k, v in sorted(self.agents.items())},
            "occupied": {
                "grid": {name: shares(self.grid_states[b]) for b, name in enumerate(names)},
                "region": {name: shares(self.fov_states[b]) for b, name in enumerate(names)},
            },
        }


def kitti_tally(root: str, sequence: str, first: int) -> Tally:
    """Fuse every scan of a KITTI sequence (no map) and tally frames ``first`` on."""
    from dstenv.kitti.grids import camera_fov, dontcare_cells
    from dstenv.kitti.readers import OBJECT_TYPES
    from dstenv.kitti.sequence import KittiSequence, convert_sequence, kitti_config
    from dstenv.sensing.cloud import cloud_sensor_grid

    cfg = kitti_config({"grid": {"height": GRID, "width": GRID, "cell_size": CELL},
                        "stride": 1, "warmup": first})
    spec = GridSpec(**cfg["grid"])
    seq = KittiSequence(root, sequence)
    fov = camera_fov(seq.calib, spec, cfg["labels"]["image_width"])
    dcb = seq.labels.select(seq.labels.is_dontcare)
    lab = cfg["labels"]
    moving = seq.moving(lab["rule"], lab["threshold"], lab["window"])
    tally = Tally(spec)
    for fr in convert_sequence(seq, cfg):
        pts = seq.scan(fr.step)
        sensor, _, _, obstacle, _ = cloud_sensor_grid(pts, spec, cfg["ground"], cfg["sensor"])
        if not np.array_equal(sensor, fr.sensor):
            raise RuntimeError(f"frame {fr.step}: the sensor grid is not reproducible")
        dc = dontcare_cells(pts, obstacle, dcb.bbox[dcb.frame == fr.step], seq.calib, spec,
                            cfg["labels"]["dontcare_dilation"])
        tally.add(fr.pignistic[MOVING], fr.labels, fr.sensor, fov & ~dc)
        sel = seq.boxes.frame == fr.step
        tally.add_agents(np.array([OBJECT_TYPES[t] for t in seq.boxes.type[sel]], dtype=object),
                         seq.boxes.centre[sel, :2], moving[sel], fov)
    return tally


def sim_config(overrides: list[str]) -> dict:
    """The cpu preset's world and sensor, without a map (``--set KEY=VALUE`` on top)."""
    from dstenv.data.cli import parse_set
    from dstenv.data.sampling import scenario_config

    base = {"grid": {"height": GRID, "width": GRID, "cell_size": CELL},
            "lidar": {"model": "hdl64"}, "gis": {"source": "none"}}
    return scenario_config("dense", _merge(base, parse_set(overrides)))


def _merge(a: dict, b: dict) -> dict:
    out = dict(a)
    for k, v in b.items():
        out[k] = _merge(out.get(k, {}), v) if isinstance(v, dict) else v
    return out


def sim_tallies(cfg: dict, drives: int, seed0: int) -> tuple[Tally, Tally]:
    """Tallies of ``drives`` 6 s autopilot drives (frames at steps 10, 20, ..., 50):
    inside the camera view and over the whole grid."""
    from dstenv.data.sampling import iter_frames
    from dstenv.grid import camera_mask
    from dstenv.pipeline import Pipeline
    from dstenv.sim.types import AgentKind

    spec = GridSpec(GRID, GRID, CELL)
    fov, every = camera_mask(spec, SIM_FOV), np.ones(spec.shape, bool)
    t_fov, t_all = Tally(spec), Tally(spec)
    seeds = iter(range(seed0, seed0 + drives))
    made: list[Pipeline] = []

    def make() -> Pipeline:
        made.append(Pipeline(cfg))
        return made[0]

    for fr in iter_frames(make, seeds, 60, 10, 10):
        t_fov.add(fr.pignistic[MOVING], fr.labels, fr.sensor, fov)
        t_all.add(fr.pignistic[MOVING], fr.labels, fr.sensor, every)
        world, thr = made[0].world, made[0].moving_threshold
        a = world.agents
        c, s = np.cos(world.ego_pose[2]), np.sin(world.ego_pose[2])
        d = a.xy - world.ego_pose[:2]
        xy = np.stack([c * d[:, 0] + s * d[:, 1], c * d[:, 1] - s * d[:, 0]], axis=1)
        kind = np.array([AgentKind(k).name.title() for k in a.kind], dtype=object)
        for t, region in ((t_fov, fov), (t_all, every)):
            t.add_agents(kind, xy, a.speed > thr, region)
    return t_fov, t_all


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--kitti-root", required=True, help="KITTI tracking folder")
    ap.add_argument("--sequence", default="0003")
    ap.add_argument("--drives", type=int, default=120, help="simulated 6 s drives (maps)")
    ap.add_argument("--seed", type=int, default=100000, help="first map seed")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="simulator override on top of the preset's world, e.g. "
                         "world.clutter.density=0")
    ap.add_argument("--out", required=True)
    args = ap.parse_args()
    t0 = time.time()
    kitti = kitti_tally(args.kitti_root, args.sequence, 10)
    t_fov, t_all = sim_tallies(sim_config(args.set), args.drives, args.seed)
    res = {
        "command": "python docs/kitti_evidence.py " + " ".join(
            f"--{k.replace('_', '-')} {v}" for k, v in vars(args).items()
            if v and k not in ("set", "out")) + "".join(f" --set {s}" for s in args.set)
        + f" --out {args.out}",
        "strong_threshold": STRONG,
        "kitti": kitti.summary(),
        "sim_camera_view": t_fov.summary(),
        "sim_all_cells": t_all.summary(),
        "seconds": round(time.time() - t0, 1),
    }
    from dstenv.io import atomic_write_text

    atomic_write_text(Path(args.out), json.dumps(res, indent=1) + "\n")
    print(json.dumps(res, indent=1))


if __name__ == "__main__":
    main()
