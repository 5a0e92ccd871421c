"""Real KITTI drives in the simulated benchmark's report (``dstenv benchmark --kitti``).

After a simulated benchmark, :func:`real_benchmark` converts KITTI tracking
sequences (every scan stored, so DST can be re-run with any parameters and the
observed cells accumulated) and scores, with the same
:func:`dstenv.segment.score.score`:

* the DST presets and ``dst (stored)``;
* ``dst-tuned`` and ``dst-complete`` with the parameters the simulated run tuned
  on its training maps (never on real frames);
* every network of the simulated run, trained only on simulated data;
* with ``real_net.frames > 0``: networks trained for real drives, on simulated
  drives at the converted grid with KITTI's label convention and the sensor grid as
  input (:mod:`dstenv.segment.realnet`), also simulated data only;
* with ``finetune_frames = N > 0``: a simulated network fine-tuned (``train.init``)
  on the labelled frames ``0 .. N-1`` of each sequence, starting from the one with
  the best mIoU on those same frames (:func:`start_scores`; with or without map
  input, whichever reads these real drives best), and
  ``dst-tuned (real frames)``: the DST parameters searched on the same frames
  (:func:`~dstenv.segment.tune.tune_dst_params`, the simulated run's budget, seed
  and scope), the non-learned counterpart of the fine-tuning. The fine-tuning's
  length is chosen among :data:`FINETUNE_EPOCHS` on the ``gap`` frames between the
  fine-tuning and the scored ones, which nothing trains on. Only frames from
  step ``N + gap`` on are then scored, for every row, so no fine-tuning or tuning
  frame (nor its immediate neighbours) is a test frame; the filter still runs
  over the earlier scans, as it would on a car.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

__all__ = ["convert_sequences", "real_benchmark", "sim_checkpoints", "start_scores",
           "tune_on_real", "REAL_TUNED", "FINETUNE_EPOCHS"]

#: label of the DST row tuned on the real fine-tuning frames
REAL_TUNED = "dst-tuned (real frames)"
#: candidate fine-tuning lengths [epochs], chosen on the frames between the fine-tuning
#: and the scored ones (5 alone until 2026-12-05)
FINETUNE_EPOCHS: tuple[int, ...] = (5, 10, 20, 40)


def sim_checkpoints(results: Mapping[str, Any]) -> dict[str, Path]:
    """Row label -> ``best.pt`` of every network a simulated run trained or scored."""
    out = {}
    for label, row in results["segmenters"].items():
        ckpt = row["describe"].get("checkpoint") if row["kind"] == "learned" else None
        if ckpt:
            path = Path(ckpt)
            out[label] = path / "best.pt" if path.is_dir() else path
    return out


def convert_sequences(root: str, sequences: Sequence[str], osm: str | None, data: Path) -> None:
    """``dstenv kitti convert`` of ``sequences`` into ``data`` with every scan stored
    (stride 1, no warm-up), so DST can be re-run; nothing when ``data`` holds a
    converted dataset already (resumes).

    Raises:
        CLIError: the conversion failed (its one-line error was printed).
    """
    from dstenv.cli import main
    from dstenv.config import CLIError

    if (data / "manifest.json").is_file():
        _same_drives(root, sequences, osm, data)
        return
    args = ["kitti", "convert", "--root", str(root), "--sequences", ",".join(sequences),
            "--stride", "1", "--warmup", "0", "--out", str(data)]
    if osm:
        args += ["--osm", str(osm)]
    if main(args) != 0:
        raise CLIError(f"--kitti {root}: converting sequences {','.join(sequences)} failed")


def _same_drives(root: str, sequences: Sequence[str], osm: str | None, data: Path) -> None:
    """Refuse a conversion in ``data`` of other drives (another root, sequences or map)."""
    from dstenv.config import CLIError
    from dstenv.data.manifest import load_manifest
    from dstenv.kitti.cli import _sequences  # one rule for sequence names: 3 -> 0003

    meta = load_manifest(data, verify="none").get("meta", {})
    here = (str(Path(meta.get("root") or "").resolve()), list(meta.get("sequences") or []),
            str(Path(meta["osm"]).resolve()) if meta.get("osm") else None)
    want = (str(Path(root).resolve()), _sequences(",".join(map(str, sequences))),
            str(Path(osm).resolve()) if osm else None)
    if here != want:
        said = (f"{here[0]} sequences {','.join(here[1])}, map {here[2] or 'none'}")
        raise CLIError(f"{data} holds the drives of another --kitti run ({said}); use "
                       "another --out, or remove that folder to convert these")


def start_scores(ckpts: Mapping[str, Path], ds: Any, picked: Sequence[int]
                 ) -> dict[str, float]:
    """Each simulated network's mIoU over the labelled cells of the fine-tuning frames
    ``picked`` of ``ds`` (classes present in their labels): how the fine-tuning's
    starting point is chosen, on those frames alone. Ensembles are left out: one
    network is fine-tuned."""
    import numpy as np
    import torch

    from dstenv.segment.evaluate import load_checkpoints
    from dstenv.segment.metrics import confusion_matrix, mean_iou
    from dstenv.segment.segmenters import EnsembleSegmenter

    from dstenv.data import ShardDataset

    samples = [ds[k] for k in picked]
    x10 = torch.stack([s["x"] for s in samples])
    y = torch.stack([s["labels"] for s in samples])
    out = {}
    for label, path in ckpts.items():
        (seg,) = load_checkpoints([path], int(x10.shape[1]))
        if isinstance(seg, EnsembleSegmenter):
            continue
        x = x10 if seg.inputs == ds.inputs else torch.stack(
            [s["x"] for s in (ShardDataset(ds.files, inputs=seg.inputs)[k] for k in picked)])
        with torch.no_grad():
            pred = torch.cat([seg.predict(x[i:i + 4]) for i in range(0, len(x), 4)])
        miou = mean_iou(confusion_matrix(pred, y, 5))
        out[label] = float(miou) if np.isfinite(miou) else -1.0
    return out


def _finetune(ckpts: Mapping[str, Path], data: Path, frames: int, epochs: Sequence[int],
              gap: int, out: Path, progress: bool, log: Callable[[str], None]
              ) -> tuple[Path, dict[str, Any]]:
    """Fine-tune the best-reading simulated network on the first ``frames`` real frames.

    ``epochs``: candidate lengths, trained one after the other in one run (each resumes
    the last: the same weights as a run of that length); with several, the one whose
    network reads the ``gap`` frames between the fine-tuning and the scored frames best
    (mIoU over their labelled cells; ties: the shorter) is kept. Those frames are never
    trained on nor scored.
    """
    import shutil

    import torch

    from dstenv.data import ShardDataset
    from dstenv.segment.shardindex import split_index
    from dstenv.segment.train import start_changed, train

    cands = sorted({int(e) for e in epochs})
    if not cands or cands[0] < 1:
        raise ValueError(f"finetune_epochs: lengths must be >= 1, got {list(epochs)}")
    ds = ShardDataset(data, split="test", inputs="fcn10")
    index, _ = split_index(ds.files)
    picked = [k for k, fr in enumerate(index) if fr["step"] < frames]
    if not picked:
        raise ValueError(f"finetune_frames {frames}: no converted frame before it")
    val = [k for k, fr in enumerate(index) if frames <= fr["step"] < frames + gap]
    if len(cands) > 1 and not val:
        raise ValueError(f"finetune_epochs {cands}: choosing a length needs real frames between "
                         "the fine-tuning and the scored ones (a gap > 0 holding frames)")
    scores = start_scores(ckpts, ds, picked)  # fcn10: it adds a network's other inputs
    if not scores:
        raise ValueError("finetune_frames: no single network to fine-tune among "
                         f"{', '.join(ckpts)} (an ensemble is not one); give one's checkpoint")
    best = max(scores, key=scores.__getitem__)  # ties: the first (the simulated run's order)
    log(f"fine-tuning start: {best} (mIoU on the {len(picked)} fine-tuning frames: "
        + ", ".join(f"{k} {v:.3f}" for k, v in scores.items()) + ")")
    spec = torch.load(ckpts[best], map_location="cpu", weights_only=True)["spec"]
    inputs = spec.get("inputs", "fcn10")
    # the network's own inputs to train on; the real labels are KITTI's already: "full"
    tds = ds if inputs == ds.inputs else ShardDataset(data, split="test", inputs=inputs)
    if start_changed(out, ckpts[best]):  # its start was trained further, or another one won
        log(f"fine-tuning {best} again: the fine-tuning in {out} started from other weights")
        for old in (*out.glob("epochs-*.pt"), out / "last.pt"):
            old.unlink()
    length: dict[int, float] = {}
    for e in cands:
        snap = out / f"epochs-{e}.pt"
        if not snap.exists():  # a rerun keeps the lengths it has (their own weights)
            last_pt = out / "last.pt"
            done = (int(torch.load(last_pt, map_location="cpu", weights_only=True)["epoch"])
                    + 1 if last_pt.exists() else 0)  # "epoch": the last finished, from 0
            if done > e:
                raise ValueError(f"{out}: holds a fine-tuning of {done} epochs but no "
                                 f"{snap.name}; remove the folder to fine-tune again")
            cfg = {"init": str(ckpts[best]), "model": spec["model"],
                   "model_kwargs": spec["model_kwargs"], "epochs": e, "batch_size": 4,
                   "lr": 1e-4, "device": "cpu", "inputs": inputs}
            log(f"fine-tuning {best} on {len(picked)} real frames, {e} epochs")
            train(cfg, torch.utils.data.Subset(tds, picked), None, out, progress=progress,
                  log=log)
            tmp = snap.with_suffix(".tmp")
            shutil.copyfile(last_pt, tmp)
            tmp.replace(snap)  # atomic: a snapshot is whole or absent
        if len(cands) > 1:
            length[e] = start_scores({"x": snap}, ds, val)["x"]
    chosen = max(cands, key=lambda e: (length.get(e, 0.0), -e))
    if len(cands) > 1:
        log(f"fine-tuning length: {chosen} epochs (mIoU on the {len(val)} frames between: "
            + ", ".join(f"{e} {v:.3f}" for e, v in length.items()) + ")")
    first, last = (index[val[0]]["step"], index[val[-1]]["step"]) if val else (None, None)
    return out / f"epochs-{chosen}.pt", {
        "start": best, "start_miou": scores,
        "epochs": {"candidates": cands, "chosen": chosen, "miou": length,
                   "chosen_on": f"frames {first}-{last}" if val else None}}


def tune_on_real(data: Path, frames: int, tune: Mapping[str, Any], progress: bool = False,
                 log: Callable[[str], None] = print) -> Any:
    """``dst-tuned (real frames)``: DST parameters searched on the labelled frames
    ``0 .. frames - 1`` of each converted drive in ``data`` (the filter runs over
    every scan before them).

    Args:
        tune: ``budget``, ``seed`` and ``scope`` of the search (a benchmark's ``tune``).

    Returns:
        A :class:`~dstenv.segment.segmenters.DSTSegmenter` labelled :data:`REAL_TUNED`
        whose ``describe()`` holds the search trace.

    Raises:
        ValueError: no converted frame before ``frames``, or drives whose stored
            scans cannot be re-filtered exactly.
    """
    from dstenv.data import ShardDataset
    from dstenv.segment.plan import split_drives, steps_before
    from dstenv.segment.segmenters import DSTSegmenter
    from dstenv.segment.tune import tune_dst_params

    drives = split_drives(ShardDataset(data, split="test", inputs="fcn10"), True, progress,
                          log)
    if drives.refilter_reason:
        raise ValueError(f"{data}: cannot tune DST on the real frames: "
                         f"{drives.refilter_reason}")
    episodes = [e for e in (steps_before(ep, frames) for ep in drives.episodes)
                if e is not None]
    if not episodes:
        raise ValueError(f"finetune_frames {frames}: no converted frame before it")
    best, trace = tune_dst_params(episodes, budget=int(tune["budget"]), seed=int(tune["seed"]),
                                  progress=progress, scope=str(tune["scope"]))
    trace["frames"] = sum(len(ep.steps) for ep in episodes)
    log(f"{REAL_TUNED}: mIoU ({trace['scope']}) on {trace['frames']} real frames "
        f"{trace['start_miou']:.3f} (default) -> {trace['best_miou']:.3f}")
    return DSTSegmenter(best, "dst-tuned", REAL_TUNED, info={"tuning": trace})


def real_benchmark(
    sim: Mapping[str, Any],
    out: Path,
    root: str,
    sequences: Sequence[str],
    osm: str | None = None,
    finetune_frames: int = 0,
    finetune_epochs: int | Sequence[int] = FINETUNE_EPOCHS,
    gap: int = 10,
    progress: bool = False,
    log: Callable[[str], None] = print,
) -> dict[str, Any]:
    """Score a simulated run's segmenters on real KITTI drives (module docstring).

    Args:
        sim: the simulated run's results.
        out: the simulated run's output directory (``kitti/`` is written inside).
        root: KITTI tracking folder; sequences: e.g. ``["0003"]``; osm: optional map.
        finetune_frames: N labelled real frames per sequence for fine-tuning (0: none).
        finetune_epochs: fine-tuning epochs, or candidate lengths chosen on the ``gap``
            frames (:data:`FINETUNE_EPOCHS`).
        gap: frames skipped between the fine-tuning and the scored frames.
        progress, log: tqdm bars, one-line messages.

    Returns:
        The real-data results (also in ``out/kitti/results.json``).
    """
    from dstenv.segment.benchmark import run_benchmark
    from dstenv.segment.presets import default_benchmark_config

    kdir = out / "kitti"
    data = kdir / "data"
    convert_sequences(root, sequences, osm, data)
    ckpts = sim_checkpoints(sim)
    facts = None
    rn = sim["config"].get("real_net", {"frames": 0})  # runs older than real_net: none
    if int(rn["frames"]) > 0:
        from dstenv.data.manifest import load_manifest
        from dstenv.segment.realnet import real_moving_speed, train_real_networks

        manifest = load_manifest(data)
        more, facts = train_real_networks(
            sim, tuple(manifest["grid_shape"]), float(manifest["cell_size"]),
            kdir / "real_net", progress, log, real_map=osm is not None,
            real_moving=real_moving_speed(manifest))
        ckpts.update(more)
    decided = {f"{k}, calibrated + free": Path(v["checkpoint"])
               for k, v in (facts or {}).get("decided", {}).items() if "checkpoint" in v}
    cfg = default_benchmark_config()
    cfg.update(models=[], device="cpu", examples=min(int(sim["config"]["examples"]), 2))
    segs = sim["segmenters"]
    if "dst-tuned" in segs:
        cfg["tune"]["params"] = dict(segs["dst-tuned"]["describe"]["params"])
    else:
        cfg["tune"]["enabled"] = False
    if "dst-complete" in segs:
        cfg["complete"]["params"] = dict(segs["dst-complete"]["describe"]["completion"])
    else:
        cfg["complete"]["enabled"] = False
    labelled = [(f"{k} (sim only)", p) for k, p in {**ckpts, **decided}.items()]
    finetuned: list[str] = []
    dst_rows = []
    start: dict[str, Any] = {}
    if finetune_frames > 0:
        cfg["score_from_step"] = finetune_frames + gap
        lengths = ([finetune_epochs] if isinstance(finetune_epochs, int)
                   else list(finetune_epochs))
        tuned, start = _finetune(ckpts, data, finetune_frames, lengths, gap,
                                 kdir / "finetune", progress, log)
        labelled.append((f"fine-tuned on {finetune_frames} real frames/sequence", tuned))
        finetuned.append(labelled[-1][0])
        dst_rows.append(tune_on_real(data, finetune_frames, sim["config"]["tune"], progress,
                                     log))
    res = run_benchmark(cfg, kdir, data_dir=data, progress=progress, log=log,
                        command=None, checkpoints=labelled, dst_rows=dst_rows,
                        finetuned=finetuned)
    res["real"] = {"root": str(root), "sequences": list(sequences), "osm": osm,
                   "finetune_frames": finetune_frames, "gap": gap,
                   "finetune_start": start if finetune_frames > 0 else None,
                   "scored_from_step": cfg["score_from_step"], "real_net": facts}
    return res
