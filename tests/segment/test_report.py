import json

import numpy as np
import pytest

from dstenv.config import ConfigError
from dstenv.dst import CLASSES
from dstenv.segment import report
from dstenv.segment.benchmark import _goal, preset_config
from dstenv.segment.metrics import summarize


def _results():
    eye = np.diag([50, 20, 30, 5, 5]).astype(np.int64)
    noisy = eye.copy()
    noisy[3, 4] = noisy[4, 3] = 5
    segs = {}
    for label, cm, kind in (("dst (default)", noisy, "dst"), ("unet-light", eye, "learned")):
        s = summarize(cm, CLASSES)
        segs[label] = {"all": s, "visible": s, "kind": kind}
    res = {
        "preset": "tiny",
        "command": "dstenv benchmark --preset tiny",
        "segmenters": segs,
        "histories": {
            "unet-light": {
                "epoch": [1, 2],
                "train_loss": [1.0, 0.5],
                "val_loss": [1.1, 0.7],
                "val_miou": [0.3, 0.6],
                "val_iou": [None, None],
            }
        },
        "data": {
            "test_frames": 4,
            "test_episodes": 2,
            "train_frames": 10,
            "val_frames": 2,
            "grid_shape": [8, 8],
            "cell_size": 0.33,
        },
    }
    res["goal"] = _goal(segs, {k: v["kind"] for k, v in segs.items()})
    return res


def test_goal_by_hand():
    g = _results()["goal"]
    # dst: static/moving IoU 5/15 = 1/3 each -> mIoU (3 + 2/3) / 5; learned: 1
    assert g["best_learned"] == "unet-light" and g["best_dst"] == "dst (default)"
    assert g["margin"] == pytest.approx(1 - (3 + 2 / 3) / 5)
    assert g["margin_met"] and g["moving_met"] and g["static_met"]


def test_markdown_and_json(tmp_path):
    res = _results()
    md = report.markdown_table(res)
    assert "| unet-light | 1.000 | 1.000 | 1.000 | 1.000 | 1.000 | **1.000** |" in md
    assert "| dst (default) | 1.000 | 1.000 | 1.000 | 0.333 | 0.333 | **0.733** |" in md
    assert "dstenv benchmark --preset tiny" in md and "visible cells only" in md
    path = report.write_json(tmp_path / "r.json", res)
    assert json.loads(path.read_text())["segmenters"]["unet-light"]["all"]["miou"] == 1.0


def test_figures_are_written(tmp_path):
    res = _results()
    assert report.plot_confusions(res, tmp_path / "cm.png").stat().st_size > 1000
    assert report.plot_curves(res["histories"], tmp_path / "curves.png").stat().st_size > 1000
    lab = np.zeros((8, 8), np.int64)
    lab[0] = 255
    ex = {
        "title": "x",
        "betp_moving": np.random.default_rng(0).random((8, 8)),
        "predictions": {"dst": lab.clip(0, 4), "unet": lab.clip(0, 4)},
        "labels": lab,
    }
    assert report.plot_examples([ex, ex], tmp_path / "ex.png").stat().st_size > 1000


def test_presets_validate():
    cfg = preset_config("cpu", {"train": {"epochs": 2}})
    assert cfg["train"]["epochs"] == 2 and cfg["models"] == ["unet-light"]
    with pytest.raises(ConfigError, match="unknown benchmark preset"):
        preset_config("tpu")
    with pytest.raises(ConfigError, match="unknown key 'frame'"):
        preset_config("cpu", {"data": {"frame": 3}})
