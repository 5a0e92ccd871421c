"""How many cells ``protocol.object_edges = "ignore"`` takes out of the labels.

The main job's world (``dense``, 3-D LIDAR, 128 x 128 cells of 0.33 m), drives of seeds
0..``--drives``-1, every 10th of 50 steps: the occupied cells just outside a road user
that :func:`dstenv.sensing.labels.ignore_object_edges` ignores, what the labels called
them, and the visible static / moving cells beside them::

    python docs/rim_cells.py --drives 3 --out docs/rim-cells.json
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--drives", type=int, default=3, help="drives (seeds 0..N-1)")
    ap.add_argument("--out", type=Path, help="also write the figures as JSON")
    args = ap.parse_args()

    from dstenv.data.sampling import scenario_config
    from dstenv.dst import CLASSES
    from dstenv.frame import IGNORE_INDEX
    from dstenv.pipeline import Pipeline
    from dstenv.sensing.labels import ignore_object_edges

    cfg = scenario_config("dense", {"lidar": {"model": "hdl64"},
                                    "grid": {"height": 128, "width": 128, "cell_size": 0.33}})
    p = Pipeline(cfg)
    objects = [CLASSES.index("static"), CLASSES.index("moving")]
    frames, rim, visible_objects = 0, 0, 0
    was = np.zeros(len(CLASSES))
    for seed in range(args.drives):
        p.reset(seed)
        for k in range(50):
            f = p.step()
            if k % 10 != 9:
                continue
            lab = f.labels.copy()
            rim += ignore_object_edges(lab, f.sensor, IGNORE_INDEX)
            was += np.bincount(f.labels[lab == IGNORE_INDEX], minlength=len(CLASSES))[:len(CLASSES)]
            visible_objects += int(np.isin(f.labels, objects)[f.visible].sum())
            frames += 1
    out = {"frames": frames, "rim_cells_per_frame": rim / frames,
           "visible_object_cells_per_frame": visible_objects / frames,
           "rim_cells_were": {c: float(v / frames) for c, v in zip(CLASSES, was)}}
    print(json.dumps(out, indent=1))
    if args.out:
        args.out.write_text(json.dumps(out, indent=1) + "\n")


if __name__ == "__main__":
    main()
