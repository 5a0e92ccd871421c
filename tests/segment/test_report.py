import json

import numpy as np
import pytest

from dstenv.config import ConfigError
from dstenv.segment import figures, report
from dstenv.segment.presets import preset_config, protocol_overrides
from dstenv.segment.results import goal, segmenter_results
from dstenv.segment.score import DISTANCE_BANDS, OBJECT_CLASSES, SCOPES, Scores


def _results():
    eye = np.diag([50, 20, 30, 5, 5]).astype(np.int64)
    noisy = eye.copy()
    noisy[3, 4] = noisy[4, 3] = 5
    # two drives on two maps, each holding half of every count
    per_drive = {"dst (default)": np.stack([noisy, noisy]), "unet-light": np.stack([eye, eye])}
    objs = np.zeros((2, len(OBJECT_CLASSES), len(DISTANCE_BANDS) - 1, 4), np.int64)
    objs[:, 0, 0] = [4, 3, 2, 2]  # per drive: 4 static objects, 3 recovered, 2/2 predicted
    scores = Scores(
        drives=[(1, 0), (2, 0)], clusters=np.array([1, 2]),
        confusion={k: {sc: v for sc in SCOPES} for k, v in per_drive.items()},
        objects={k: objs for k in per_drive}, ties=np.zeros((2, 2), np.int64),
        frames=np.array([2, 2]),
    )
    kinds = {"dst (default)": "dst", "unet-light": "learned"}
    segs, conf, weights = segmenter_results(scores, kinds, {k: {"name": k} for k in kinds},
                                            resamples=50)
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
        "data": {"test_frames": 4, "test_episodes": 2, "test_maps": 2, "train_frames": 10,
                 "val_frames": 2, "grid_shape": [8, 8], "cell_size": 0.33},
    }
    res["goal"] = goal(segs, conf, weights)
    return res


def test_goal_by_hand():
    g = _results()["goal"]
    # dst: static/moving IoU 10/30 = 1/3 each -> mIoU (3 + 2/3) / 5; learned: 1
    assert g["best_learned"] == "unet-light" and g["best_baseline"] == "dst (default)"
    assert g["scope"] == "observed"
    assert g["margin"] == pytest.approx(1 - (3 + 2 / 3) / 5)
    # both drives are alike: every resample gives the same margin
    assert g["margin_ci"] == pytest.approx([g["margin"]] * 2)
    assert g["moving_diff"] == pytest.approx(2 / 3)
    assert g["margin_met"] and g["moving_met"] and g["static_met"]


def test_object_summary_and_seedless_rows():
    o = _results()["segmenters"]["unet-light"]["objects"]["static"]
    assert o["objects"] == 8 and o["recall"] == pytest.approx(6 / 8)
    assert o["precision"] == 1.0 and o["bands"][0]["range_m"] == [0.0, 10.0]
    assert o["bands"][-1]["range_m"][1] is None


def test_markdown_and_json(tmp_path):
    res = _results()
    md = report.markdown_table(res)
    assert ("| unet-light | learned | 1.000 | 1.000 | 1.000 | 1.000 [1.000, 1.000] | "
            "1.000 [1.000, 1.000] | **1.000 [1.000, 1.000]** |") in md
    assert "| dst (default) | dst | 1.000 | 1.000 | 1.000 | 0.333 [0.333, 0.333] |" in md
    assert md.index("observed cells (headline") < md.index("all labelled cells (amodal")
    assert "dstenv benchmark --preset tiny" in md and "(tiny preset)" in md
    path = report.write_json(tmp_path / "r.json", res)
    assert json.loads(path.read_text())["segmenters"]["unet-light"]["all"]["miou"] == 1.0


def test_real_data_report_has_no_preset_or_goal_line():
    res = _results()
    res.update(preset=None, goal=None, command="dstenv benchmark --data kitti --out r")
    res["data"].update(evaluation_only=True, source="kitti")
    md = report.markdown_table(res)
    assert "preset" not in md and "## Goal" not in md and "--preset" not in md
    assert md.startswith("# Segmenter benchmark on kitti data")
    assert "## Notes" not in md
    # notes reach the report too (kitti evaluate runs quiet: the log line alone was lost)
    res["notes"] = ["note: best.pt was trained on cells of 1 m, these drives have 0.33 m"]
    assert "## Notes\n\n- note: best.pt was trained on cells of 1 m" in report.markdown_table(res)


def test_figures_are_written(tmp_path):
    res = _results()
    assert figures.plot_confusions(res, tmp_path / "cm.png").stat().st_size > 1000
    assert figures.plot_curves(res["histories"], tmp_path / "curves.png").stat().st_size > 1000
    lab = np.zeros((8, 8), np.int64)
    lab[0] = 255
    ex = {
        "title": "x",
        "betp_moving": np.random.default_rng(0).random((8, 8)),
        "predictions": {"dst": lab.clip(0, 4), "unet": lab.clip(0, 4)},
        "labels": lab,
    }
    assert figures.plot_examples([ex, ex], tmp_path / "ex.png").stat().st_size > 1000
    # long row labels wrap in the panel titles (the KITTI rows ran into each other);
    # the simulated rows' short ones stay as they are, so their figures do not change
    assert figures._title("unet-light no-map") == "unet-light no-map"
    assert figures._title("unet-light kitti-labels (seed 0) (sim only)") == (
        "unet-light kitti-labels\n(seed 0) (sim only)")
    seg = res["segmenters"]["unet-light"]
    res["curve"] = [{"train_frames": n, **seg} for n in (140, 1400)]
    assert figures.plot_size_curve(res, tmp_path / "c.png").stat().st_size > 1000
    assert "| 1400 | 1.000 [1.000, 1.000] |" in report.markdown_table(res)


def test_presets_validate():
    cfg = preset_config("cpu", {"train": {"epochs": 2}})
    assert cfg["train"]["epochs"] == 2 and cfg["models"] == ["unet-light"]
    with pytest.raises(ConfigError, match="unknown benchmark preset"):
        preset_config("tpu")
    with pytest.raises(ConfigError, match="unknown key 'frame'"):
        preset_config("cpu", {"data": {"frame": 3}})
    from dstenv.segment.presets import check_config as _check

    with pytest.raises(ConfigError, match="search.key: 'speed' is not a training option"):
        _check(preset_config("tiny", {"search": {"key": "speed", "values": [1]}}))
    with pytest.raises(ConfigError, match="train_seeds"):
        _check(preset_config("tiny", {"train_seeds": [1, 1]}))
    with pytest.raises(ConfigError, match="real_net.map: unknown 'osm'; choose from match, run"):
        _check(preset_config("tiny", {"real_net": {"map": "osm"}}))
    with pytest.raises(ConfigError, match="real_net.inputs: unknown 'fcn10'; choose from "
                                          "fcn10[+]sensor, fcn10[+]sensor[+]past"):
        _check(preset_config("tiny", {"real_net": {"inputs": "fcn10"}}))
    with pytest.raises(ConfigError, match="real_net.moving: unknown 'kitti'; choose from "
                                          "match, run"):
        _check(preset_config("tiny", {"real_net": {"moving": "kitti"}}))
    # free-form tables stay free-form over a preset that already set keys in them
    cfg = preset_config("cpu", {"data": {"overrides": {"protocol": {"object_edges": "ignore"}}}})
    assert cfg["data"]["overrides"]["protocol"] == {"object_edges": "ignore"}
    assert cfg["data"]["overrides"]["lidar"] == {"model": "hdl64"}  # the preset's, kept
    cfg = preset_config("smoke", {"model_kwargs": {"unet-light": {"betp_skip": 1.0}}})
    assert cfg["model_kwargs"]["unet-light"]["betp_skip"] == 1.0
    with pytest.raises(ConfigError, match="data.overrides.protocol.bogus: unknown key 'bogus'"):
        _check(preset_config("cpu", {"data": {"overrides": {"protocol": {"bogus": 1}}}}))


def test_paper_protocol_names_missing_pipeline_keys():
    from dstenv.pipeline import default_config

    assert protocol_overrides("sim") == {}
    with pytest.raises(ConfigError, match="choose from sim, paper"):
        protocol_overrides("kitti")
    if "protocol" in default_config():
        assert protocol_overrides("paper")["protocol"]["update_every"] == 10
        from dstenv.segment.presets import check_config as _check

        with pytest.raises(ConfigError, match="data.stride = 4: the paper protocol fuses every 10"):
            _check(preset_config("tiny", {"protocol": "paper"}))
    else:
        with pytest.raises(ConfigError, match=r"protocol.*\(1 Hz fusion.*issue 13"):
            protocol_overrides("paper")


def test_kitti_section_says_which_frames_trained_what(tmp_path) -> None:
    """With ``--finetune-frames`` the KITTI section names the fine-tuning's starting
    network, every candidate's mIoU on those frames and the real-frame DST search."""
    from pathlib import Path

    committed = Path(__file__).resolve().parents[2] / "benchmarks" / "results" / "cpu"
    kitti = json.loads((committed / "results.json").read_text())["kitti"]
    md = report.markdown_table({**kitti, "command": None})
    start = kitti["real"]["finetune_start"]
    tuning = kitti["segmenters"]["dst-tuned (real frames)"]["describe"]["tuning"]
    assert start["start"] == max(start["start_miou"], key=start["start_miou"].get)
    line = next(x for x in md.splitlines() if x.startswith("Frames 0-9 of each sequence"))
    assert f"starts from {start['start']}" in line
    for name, miou in start["start_miou"].items():
        assert f"{name} {miou:.3f}" in line
    assert f"({tuning['budget']} sets, observed cells: mIoU {tuning['start_miou']:.3f}" in line
    assert f"scored from step {kitti['real']['scored_from_step']} on" in line
    assert tuning["frames"] == 10 and kitti["real"]["scored_from_step"] == 20
    # without fine-tuning frames there is no such line
    plain = {**kitti, "real": {**kitti["real"], "finetune_frames": 0}, "command": None}
    assert "Frames 0-" not in report.markdown_table(plain)
    # the committed results.md is what the code writes for this section
    assert line in (committed / "results.md").read_text()


def test_real_report_names_the_decision_rules():
    """The KITTI report says how the ``calibrated + free`` rows decide, with each offset,
    and that an ensemble averages before deciding (only when there is one)."""
    from dstenv.segment.report import _real_lines

    net = {"frames": {"train": 8, "val": 2}, "grid": [4, 4], "cell_size": 0.33,
           "no_map": True, "checkpoints": {"n (seed 0)": "a", "n (seed 1)": "b"},
           "decided": {"n (seed 0)": {"checkpoint": "x", "moving_offset": -1.5},
                       "n (seed 1)": {"unchosen": "no visible moving cell"}}}
    text = " ".join(_real_lines({"real": {"real_net": net}}))
    assert "offsets: n (seed 0) -1.5), then the free-space rule." in text
    assert "seed 1) -" not in text and "ensemble" not in text
    net["decided"]["n ensemble of 2 seeds"] = {"checkpoint": "e", "moving_offset": -0.25,
                                               "members": ["n (seed 0)", "n (seed 1)"]}
    text = " ".join(_real_lines({"real": {"real_net": net}}))
    assert "n ensemble of 2 seeds -0.25), then the free-space rule; an ensemble averages" in text
