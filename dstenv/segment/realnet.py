"""A simulated network made for real drives (``dstenv benchmark --kitti``, ``real_net``).

The simulated benchmark's networks learn the simulator's task: five classes on every
cell of a 42 m grid, from the filter's BetP alone. Real KITTI drives ask another one,
and three differences cost them most on KITTI 0003 (``docs/benchmark.md``, "A network
for real drives"):

* **Extent.** The conversion's grid is 256 cells (84 m); every parked car of 0003 is
  beyond the 21 m a 128-cell simulated grid reaches, where returns are sparse and rims
  carry moving evidence. The data here is generated at the converted grid and cell
  size.
* **Labels.** KITTI labels boxes and the free ground it sees, nothing else
  (:func:`dstenv.kitti.grids.kitti_convention`); a network trained on the simulator's
  five classes spends its decisions on walls and verges, and calls real cars'
  cells ``non_navigable``. Trained on the same convention it learns the real task.
* **What is seen now.** The filter keeps moving mass on cells a car has just left;
  the current sensor grid (``inputs = "fcn10+sensor"``) tells the network the cell is
  free now.
* **No map.** Drives converted without an OSM file have a vacuous GIS grid; with
  ``real_net.map = "match"`` every simulated drive is then fused without a map too
  (the simulated run has a map in most drives), so the network never learns to lean on
  map evidence the real drives lack.
* **How it decides.** Training seeds differ most in how readily they call a still object
  moving; with ``real_net.decide`` each network is also scored with a static/moving
  offset chosen on its own simulated validation drives and the free-space rule
  (:mod:`dstenv.segment.decide`), rows ``... calibrated + free``.
  With ``real_net.ensemble`` the seeds' ensemble (the mean of their logits) is scored
  too, its offset chosen the same way on its own scores (:func:`_ensemble`).
* **What moves.** KITTI's labels call an object moving above 10 cm a 0.1 s frame
  (1 m/s, :func:`dstenv.kitti.objects.moving_flags`); the simulator's above 0.1 m/s, so
  a car creeping in a queue is moving there and static in KITTI. With
  ``real_net.moving = "match"`` the drives label agents by the real labels' speed
  (from the converted data's manifest).

:func:`train_real_networks` generates the data (the simulated run's scenario,
overrides and protocol; other map seeds) and trains one network per seed; it resumes
like the benchmark. Nothing here sees a real frame.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from dstenv.config import ConfigError

__all__ = ["REAL_NET", "real_net_label", "real_moving_speed", "train_real_networks"]

#: name of the networks' rows (with ``(seed N)`` when several seeds are trained)
REAL_NET = "kitti-labels"

#: map seeds of the generated drives start here (the simulated run's are 0 ..)
_SEED_OFFSET = 1_000_000


def real_net_label(model: str, seed: int, seeds: int) -> str:
    """Row label of the network of ``seed`` (``seeds``: how many were trained)."""
    base = f"{model} {REAL_NET}"
    return base if seeds == 1 else f"{base} (seed {seed})"


def real_moving_speed(manifest: Mapping[str, Any]) -> float:
    """The speed above which converted real data's labels call an object moving [m/s]:
    the converter's ``labels.threshold`` (per frame) times
    :data:`~dstenv.kitti.sequence.FRAME_RATE`; the converter's default when
    ``manifest`` does not record it."""
    from dstenv.kitti.sequence import FRAME_RATE, default_config

    labels = manifest.get("meta", {}).get("config", {}).get("labels", {})
    threshold = labels.get("threshold", default_config()["labels"]["threshold"])
    return float(threshold) * FRAME_RATE


def train_real_networks(
    sim: Mapping[str, Any],
    grid: tuple[int, int],
    cell_size: float,
    out: Path,
    progress: bool = False,
    log: Callable[[str], None] = print,
    real_map: bool = False,
    real_moving: float | None = None,
) -> tuple[dict[str, Path], dict[str, Any]]:
    """Generate simulated drives at the real data's grid and train the networks.

    Args:
        sim: the simulated run's results (its ``config``: ``data``, ``protocol``,
            ``train`` and ``real_net``).
        grid: ``(H, W)`` cells of the converted real data; must be square.
        cell_size: its cell size [m].
        out: where ``data/`` and ``models/seedN/`` go.
        progress, log: tqdm bars, one-line messages.
        real_map: whether the real drives were converted with a map. Without one and
            with ``real_net.map = "match"`` (the default) every simulated drive is
            fused without a map too (``gis.source = "none"``), as the network will
            read the real ones.
        real_moving: the speed above which the real labels call an object moving
            [m/s] (:func:`real_moving_speed`); with ``real_net.moving = "match"`` the
            drives label agents by it (``None``: the simulated run's rule).

    Returns:
        ``({row label: best.pt}, facts for results.json)``.

    Raises:
        ValueError: a non-square grid.
    """
    from dstenv.data import ShardDataset
    from dstenv.segment.benchmark import generate_data
    from dstenv.segment.train import resolve_device, train

    from dstenv.data.datasets import PAST_STEPS

    cfg = sim["config"]
    rn = cfg["real_net"]
    if grid[0] != grid[1]:
        raise ValueError(f"real_net: the real data's grid {grid} is not square")
    stride = int(cfg["data"]["stride"])
    if "past" in rn.get("inputs", "") and PAST_STEPS % stride:
        raise ConfigError(f"real_net.inputs {rn['inputs']!r} read the frame {PAST_STEPS} steps "
                          f"before each, which data.stride = {stride} never stores: use a "
                          f"stride that divides {PAST_STEPS}, or real_net.inputs = fcn10+sensor")
    t = time.perf_counter()
    dcfg = {**cfg["data"], "frames": int(rn["frames"]), "grid": int(grid[0]),
            "seed": int(cfg["data"]["seed"]) + _SEED_OFFSET}
    no_map = rn.get("map", "match") == "match" and not real_map
    # runs older than real_net.moving labelled by the run's rule
    moving = real_moving if rn.get("moving", "run") == "match" else None
    log(f"real_net: generating {dcfg['frames']} simulated frames at {grid[0]} x {grid[1]} "
        f"cells of {cell_size:g} m{' without a map' if no_map else ''}"
        + (f", moving above {moving:g} m/s" if moving is not None else "")
        + f" into {out / 'data'}")
    generate_data(dcfg, cfg["protocol"], out / "data", progress, cell_size, no_map, moving)
    timings = {"data_s": time.perf_counter() - t}
    inputs = rn.get("inputs", "fcn10+sensor")  # runs older than real_net.inputs: this one
    data = {s: ShardDataset(out / "data", split=s, inputs=inputs, labels="kitti")
            for s in ("train", "val")}
    seeds = [int(s) for s in rn["seeds"]]
    ckpts, histories = {}, {}
    for seed in seeds:
        t = time.perf_counter()
        label = real_net_label(rn["model"], seed, len(seeds))
        tcfg = {**cfg["train"], "model": rn["model"],
                "model_kwargs": cfg["model_kwargs"].get(rn["model"], {}),
                "epochs": int(rn["epochs"]), "seed": seed,
                "device": str(resolve_device(cfg["device"])),
                "inputs": inputs, "labels": "kitti", "init": ""}
        mdir = out / "models" / f"seed{seed}"
        log(f"real_net: training {label} on {len(data['train'])} frames")
        _, histories[label] = train(tcfg, data["train"], data["val"] if len(data["val"]) else None,
                                    mdir, progress=progress, log=log)
        timings[f"train_{label}_s"] = time.perf_counter() - t
        ckpts[label] = mdir / "best.pt"
    decided = {}
    if rn.get("decide", False) and len(data["val"]):  # runs older than real_net.decide: off
        from dstenv.segment.decide import decide_checkpoint

        on = f"the simulated validation drives in {out / 'data'}"
        for label, best in ckpts.items():
            decided[label] = _decided(
                label, best.parent / "decided.pt", log,
                lambda b=best: decide_checkpoint(b, b.parent / "decided.pt", data["val"], on),
                "(least confusion on the simulated validation drives)")
        if rn.get("ensemble", False) and len(ckpts) >= 2:  # runs older: none
            decided.update(_ensemble(f"{rn['model']} {REAL_NET} ensemble of {len(ckpts)} "
                                     "seeds", ckpts, out, data["val"], log))
    facts = {"data": str(out / "data"), "grid": list(grid), "cell_size": cell_size,
             "frames": {s: len(d) for s, d in data.items()}, "seeds": seeds,
             "inputs": inputs, "labels": "kitti", "no_map": no_map,
             "moving_threshold": moving,
             "checkpoints": {k: str(v) for k, v in ckpts.items()}, "decided": decided,
             "histories": histories, "timings_s": timings}
    return ckpts, facts


def _decided(label: str, path: Path, log: Callable[[str], None],
             decide: Callable[[], dict[str, Any]], how: str) -> dict[str, Any]:
    """The facts of a decided row: ``decide()`` writes ``path`` and returns the decision
    (``how`` its offset was chosen, for the log); ``{"unchosen": why}`` when it cannot
    choose one (e.g. no visible moving cell in a tiny validation split)."""
    try:
        rule = decide()
    except ValueError as exc:
        log(f"real_net: {label}: no decision rule ({exc})")
        return {"unchosen": str(exc)}
    log(f"real_net: {label}: static/moving offset {rule['moving_offset']:+g} {how}, "
        "free-space rule")
    return {"checkpoint": str(path), "moving_offset": rule["moving_offset"]}


def _ensemble(label: str, ckpts: Mapping[str, Path], out: Path, val: Any,
              log: Callable[[str], None]) -> dict[str, dict[str, Any]]:
    """``{label: facts}`` of the ensemble of the networks ``ckpts`` (``out/models/
    ensemble.pt``, :func:`dstenv.segment.decide.decide_ensemble`) calibrated on ``val``;
    ``{"unchosen": why}`` when nothing there can choose its offset."""
    from dstenv.segment.decide import decide_ensemble

    path = out / "models" / "ensemble.pt"
    row = _decided(label, path, log, lambda: decide_ensemble(
        list(ckpts.values()), path, val, f"the simulated validation drives in {out / 'data'}"),
        "on the mean of the seeds' scores")
    return {label: {**row, "members": list(ckpts)} if "checkpoint" in row else row}
