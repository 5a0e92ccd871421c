"""Fine-tuning lengths and rates on KITTI 0003: trained on frames 0-9, read on 10-19 (never
trained on, never scored), scored on 20-39 over visible cells, as the main job's KITTI
section does (issue 14)::

    python docs/finetune_sweep.py START.pt KITTI_DATA OUT_DIR

START: a simulated network (the main job's ``kitti-labels`` seed 0); KITTI_DATA: the
converted sample (``kitti convert --stride 1 --warmup 0``, as the main job converts it).
Writes ``OUT_DIR/sweep.json``; each setting is a fresh fine-tuning run. ``--scratch``
trains the same network from random weights on the same ten frames instead (the
control: what the simulated pretraining adds), at the rates 1e-4 and 1e-3.
"""

import sys

if __name__ == "__main__" and {"-h", "--help"} & set(sys.argv[1:]):  # usage: the docstring
    print(__doc__)
    raise SystemExit(0)
import json
import sys
import time
from pathlib import Path

import torch

from dstenv.data import ShardDataset
from dstenv.segment.checkpoint import load_segmenter
from dstenv.segment.shardindex import split_index
from dstenv.segment.metrics import confusion_matrix, iou_per_class, mean_iou
from dstenv.segment.train import train

scratch = "--scratch" in sys.argv
argv = [a for a in sys.argv[1:] if a != "--scratch"]
start, kdata, out = argv[0], argv[1], Path(argv[2])
spec = torch.load(start, map_location="cpu", weights_only=True)["spec"]
inputs = spec.get("inputs", "fcn10")
ds = ShardDataset(kdata, split="test", inputs=inputs)
index, _ = split_index(ds.files)
ft = [k for k, fr in enumerate(index) if fr["step"] < 10]
val = [k for k, fr in enumerate(index) if 10 <= fr["step"] < 20]
test = [k for k, fr in enumerate(index) if fr["step"] >= 20]
items = {k: ds[k] for k in val + test}

def scores(path, frames):
    seg = load_segmenter(path, "cpu")
    seg.model.eval()
    with torch.no_grad():
        pred = torch.cat([seg.model(torch.stack([items[k]["x"] for k in frames[i:i + 4]]))
                          .argmax(1) for i in range(0, len(frames), 4)])
    y = torch.stack([items[k]["labels"] for k in frames])
    m = torch.stack([items[k]["visible"] for k in frames])
    cm = confusion_matrix(pred, y, 5, m)
    iou = iou_per_class(cm)
    return {"static": round(float(iou[3]), 3), "moving": round(float(iou[4]), 3),
            "miou": round(float(mean_iou(cm)), 3)}

res = {"command": "python docs/finetune_sweep.py " + " ".join(sys.argv[1:]), "start": start,
       "scratch": scratch, "start_val": scores(start, val), "start_test": scores(start, test),
       "runs": []}
print(res, flush=True)
for lr in ((1e-4, 1e-3) if scratch else (1e-4, 3e-4)):
    for ep in (5, 10, 20, 40):
        d = out / f"lr{lr:g}-ep{ep}"
        cfg = {"init": "" if scratch else start, "model": spec["model"],
               "model_kwargs": spec["model_kwargs"], "epochs": ep, "batch_size": 4, "lr": lr,
               "device": "cpu", "inputs": inputs}
        t = time.perf_counter()
        train(cfg, torch.utils.data.Subset(ds, ft), None, d, progress=False, log=lambda m: None)
        r = {"lr": lr, "epochs": ep, "val": scores(d / "last.pt", val),
             "test": scores(d / "last.pt", test), "s": round(time.perf_counter() - t, 1)}
        res["runs"].append(r)
        print(r, flush=True)
(out / "sweep.json").write_text(json.dumps(res, indent=1) + "\n")
