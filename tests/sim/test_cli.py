"""``dstenv render`` and the world benchmark (smoke runs; no timings asserted)."""

import argparse

import numpy as np

from dstenv.cli import main
from dstenv.sim.bench import run


def test_render_writes_a_png(tmp_path):
    out = tmp_path / "scene.png"
    assert main(["render", "--scenario", "parking", "--seed", "1", "--steps", "3",
                 "--extent", "40", "--out", str(out)]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not list(tmp_path.glob("*.png.tmp*"))


def test_render_takes_set_overrides(tmp_path, capsys):
    out = tmp_path / "lots.png"
    assert main(["render", "--scenario", "dense", "--seed", "3", "--no-lidar", "--set",
                 "world.map.lot_prob=0.5", "--out", str(out)]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert main(["render", "--set", "world.map.lot_prob=2", "--out", str(tmp_path / "x.png")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "world.map.lot_prob: must be in [0, 1]" in err[0]


def test_render_refuses_settings_it_would_not_draw(tmp_path, capsys):
    # they used to be accepted and ignored: the same picture as without them
    for item, words in (("lidar.model=hdl64", "lidar.model = 'hdl64' is not drawn"),
                        ("source=highway", "source = 'highway' is not drawn")):
        assert main(["render", "--set", item, "--out", str(tmp_path / "x.png")]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and words in err
    assert not list(tmp_path.iterdir())


def test_render_refuses_a_name_that_is_not_png(tmp_path, capsys):
    # the picture is a PNG: a .jpg name would hold PNG bytes; refused before any work
    assert main(["render", "--scenario", "clean", "--out", str(tmp_path / "x.jpg")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "give a name ending in .png" in err
    assert not list(tmp_path.iterdir())


def test_render_unknown_scenario_is_a_clean_error(tmp_path, capsys):
    assert main(["render", "--scenario", "atlantis", "--out", str(tmp_path / "x.png")]) == 2
    err = capsys.readouterr().err
    assert "unknown scenario 'atlantis'" in err and "default" in err


def test_world_benchmark_reports_each_stage():
    res = run(argparse.Namespace(quick=True, repeats=2))
    assert 30 <= res["agents"] <= 50
    for key in ("world step", "reference np.sin(256x256)"):
        assert res[key]["ms"] > 0 and np.isfinite(res[key]["x_ref"])
        assert 0 < res[key]["min_ms"] <= res[key]["ms"]


def test_render_checks_its_numbers_before_drawing(tmp_path, capsys):
    out = tmp_path / "scene.png"
    for flag, value, message in (("--seed", "-1", "--seed must be in [0, 2**63)"),
                                 ("--steps", "-5", "--steps must be in 0..100000"),
                                 ("--extent", "nan", "--extent must be a size in metres"),
                                 ("--extent", "-5", "--extent must be a size in metres"),
                                 ("--extent", "1e308", "in [0, 100000]")):
        assert main(["render", "--out", str(out), flag, value]) == 2, flag
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1, err
    assert not out.exists()



def test_render_refuses_set_keys_it_would_not_use(tmp_path, capsys):
    from dstenv.cli import main

    out = tmp_path / "r.png"
    assert main(["render", "--out", str(out), "--set", "grid.height=40"]) == 2
    assert "uses no grid settings; set world or lidar keys only" in capsys.readouterr().err
    assert not out.exists()


def test_the_render_legend_is_beside_the_map_not_on_it():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from dstenv.sim.cli import LEGEND, draw_legend

    fig, ax = plt.subplots(figsize=(11, 9))
    try:
        draw_legend(ax, lidar=True)
        fig.tight_layout()  # as render_png
        fig.canvas.draw()
        legend = ax.get_legend()
        box, axes = legend.get_window_extent(), ax.get_window_extent()
        assert box.x0 >= axes.x1  # right of the map: no corner of it hidden
        assert box.x1 <= fig.bbox.x1  # and inside the figure (tight_layout makes room)
        assert len(legend.get_texts()) == len(LEGEND) + 1
    finally:
        plt.close(fig)
