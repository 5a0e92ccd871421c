"""Why a network trained on simulated 3-D-LIDAR grids misses KITTI's moving cars (issue 14).

Reads a finished ``dstenv benchmark ... --kitti`` run folder (its checkpoint, its
simulated test split and its converted KITTI frames) and writes the figures that
``docs/benchmark.md`` ("KITTI transfer") quotes::

    python docs/kitti_transfer.py --run RUN --out docs/kitti-transfer.json \\
        --figure docs/img/kitti-transfer.png

For the cells labelled moving and visible in the current sweep, on KITTI and on the
simulated test drives without a map (the KITTI sample has none), it reports the mean
network input (BetP at t and t-1, classes in CLASSES order) and the share of those
cells the network gives to each class, and, split by the class the network gives
them, the same means and how often DST's own argmax is moving there; the same for
the static cells; and, for the
simulated drives, which labels the cells with strong moving evidence
(BetP(moving) > 0.45) carry: DST's moving false alarms on clutter and facades.
The figure zooms on two KITTI frames: inputs, visible labels and the predictions of
seed 0 of ``unet-light`` and of ``unet-light no-map`` (when the run trained it).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import torch

from dstenv.data.datasets import ShardDataset
from dstenv.dst.frame import CLASSES
from dstenv.segment.checkpoint import load_segmenter

MOVING, STATIC = CLASSES.index("moving"), CLASSES.index("static")
N = len(CLASSES)


def _r(v: np.ndarray) -> list[float]:
    return [round(float(a), 3) for a in v]


def no_map(x: torch.Tensor) -> bool:
    """A frame fused without map: most cells keep a near-uniform BetP (vacuous map)."""
    return bool((x[:N].max(0).values < 0.21).float().mean() > 0.2)


def cell_stats(seg, ds: ShardDataset, keep) -> dict:
    """Mean inputs and prediction shares on visible moving and static cells."""
    out = {}
    for name, c in (("moving", MOVING), ("static", STATIC)):
        out[name] = {"feat": [], "pred": np.zeros(N), "called": []}
    frames = 0
    for k in range(len(ds)):
        s = ds[k]
        if not keep(s["x"]):
            continue
        frames += 1
        p = seg.predict(s["x"][None])[0].numpy()
        lab, vis = s["labels"].numpy(), s["visible"].numpy()
        for name, c in (("moving", MOVING), ("static", STATIC)):
            m = (lab == c) & vis
            out[name]["feat"].append(s["x"][:, m].numpy().T)
            out[name]["pred"] += np.bincount(p[m], minlength=N)
            out[name]["called"].append(p[m])
    res: dict = {"frames": frames}
    for name, st in out.items():
        f = np.concatenate(st["feat"]) if st["feat"] else np.zeros((0, 2 * N))
        res[name] = {
            "visible_cells": int(len(f)),
            "mean_betp_t": _r(f[:, :N].mean(0)) if len(f) else None,
            "mean_betp_t_prev": _r(f[:, N:].mean(0)) if len(f) else None,
            "predicted_share": dict(zip(CLASSES, np.round(st["pred"] / max(1, st["pred"].sum()),
                                                          3).tolist())),
            "by_prediction": by_prediction(f, np.concatenate(st["called"]) if st["called"]
                                           else np.zeros(0, np.int64)),
        }
    return res


def by_prediction(feat: np.ndarray, called: np.ndarray) -> dict:
    """Per class the network called the cells: how many, their mean BetP at t and t-1,
    and the share whose BetP at t has its argmax on moving (what DST would say)."""
    out = {}
    for c, name in enumerate(CLASSES):
        m = called == c
        if m.any():
            out[name] = {"cells": int(m.sum()), "mean_betp_t": _r(feat[m, :N].mean(0)),
                         "mean_betp_t_prev": _r(feat[m, N:].mean(0)),
                         "dst_argmax_moving": round(float((feat[m, :N].argmax(1)
                                                           == MOVING).mean()), 3)}
    return out


def moving_evidence_labels(ds: ShardDataset, step: int = 2) -> dict:
    """Labels of visible cells with BetP(moving) > 0.45 (every ``step``-th frame)."""
    cnt = np.zeros(N)
    for k in range(0, len(ds), step):
        s = ds[k]
        hi = (s["x"][MOVING] > 0.45).numpy() & s["visible"].numpy()
        lab = s["labels"].numpy()[hi]
        cnt += np.bincount(lab[lab < N], minlength=N)
    return dict(zip(CLASSES, np.round(cnt / max(1, cnt.sum()), 3).tolist()))


def frame_number(ds: ShardDataset, k: int) -> int:
    from dstenv.data.reader import ShardReader

    path, i = ds.locate(k)
    with ShardReader(path) as r:
        return int(r.get(i, ["step"])["step"])


def figure(segs: dict, ds: ShardDataset, frames: list[int], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from dstenv.palette import label_image

    def classes(lab, vis=None):  # RGB; ignored cells pink, cells not visible now black
        lab = np.asarray(lab)
        img = label_image(lab)
        img[lab >= N] = (255, 200, 225)
        if vis is not None:
            img[~np.asarray(vis)] = 0
        return img

    cols = 4 + len(segs)
    fig, ax = plt.subplots(len(frames), cols, figsize=(3 * cols, 4.6 * len(frames)),
                           squeeze=False)
    for r, k in enumerate(frames):
        s = ds[k]
        x = s["x"]
        c = x.shape[-1] // 2
        sl = (slice(c - 60, c), slice(c - 15, c + 25))  # 20 m x 13 m ahead, right side
        panels = [("\nBetP(moving) at t", x[MOVING].numpy()),
                  ("\nBetP(static) at t", x[STATIC].numpy()),
                  ("\nBetP(navigable) at t", x[0].numpy()),
                  ("labels (visible now)\nblack: not visible, pink: ignored",
                   classes(s["labels"], s["visible"]))]
        panels += [(f"\n{name} (sim only)", classes(seg.predict(x[None])[0].numpy()))
                   for name, seg in segs.items()]
        for j, (title, im) in enumerate(panels):
            a = ax[r, j]
            a.imshow(im[sl], vmin=0, vmax=1, interpolation="nearest")
            a.set_title(f"KITTI 0003 frame {frame_number(ds, k)}: {title}", fontsize=8)
            a.axis("off")
    fig.tight_layout()
    from dstenv.io import atomic_path

    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=70, format="png")
    plt.close(fig)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--run", required=True, help="dstenv benchmark --kitti output folder")
    ap.add_argument("--out", required=True)
    ap.add_argument("--figure")
    args = ap.parse_args()
    torch.set_num_threads(1)
    run = Path(args.run)
    kitti = ShardDataset(run / "kitti" / "data", split="test")
    sim = ShardDataset(run / "data", split="test")
    res: dict = {
        "command": "python docs/kitti_transfer.py " + " ".join(
            f"--{k} {v}" for k, v in vars(args).items() if v),
        "networks": {},
        "sim_strong_moving_evidence_labels": moving_evidence_labels(sim),
    }
    segs = {}
    for name in ("unet-light", "unet-light-no-map"):  # seed 0 of each, as the KITTI rows
        ckpt = run / "models" / name / "seed0" / "best.pt"
        if not ckpt.is_file():
            continue
        segs[name] = seg = load_segmenter(ckpt)
        res["networks"][name] = {
            "checkpoint": str(ckpt),
            "kitti": cell_stats(seg, kitti, lambda x: True),
            "sim_no_map": cell_stats(seg, sim, no_map),
            "sim_with_map": cell_stats(seg, sim, lambda x: not no_map(x)),
        }
    from dstenv.io import atomic_write_text

    atomic_write_text(Path(args.out), json.dumps(res, indent=1) + "\n")
    if args.figure:
        figure(segs, kitti, [15, 30], Path(args.figure))
    print(json.dumps(res, indent=1))


if __name__ == "__main__":
    main()
