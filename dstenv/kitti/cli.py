"""``dstenv kitti``: convert KITTI tracking sequences to shards, render and score them.

::

    dstenv kitti convert --root DIR --sequences 0003,0005 [--osm FILE] [--stride K]
                         [--warmup K] [--update-every K] [--label-rule paper|smoothed]
                         [--free-label navigable|ignore] [--split test] --out DIR
    dstenv kitti render  --root DIR --sequence 0003 --frame 25 [...] --out frame.png
    dstenv kitti evaluate --data DIR [--checkpoint best.pt ...]

``convert`` writes one shard per sequence (``DIR/<split>/kitti-SSSS.h5``, the format
of ``dstenv generate``) and ``DIR/manifest.json``. ``evaluate`` is an alias of
``dstenv benchmark --data DIR [--checkpoint PT]``: the same scoring and report.
"""

from __future__ import annotations

import argparse
import json
import re
import logging
from pathlib import Path
from typing import Any

__all__ = ["register"]

_NO_MAP = ("no map: GIS grid vacuous (all 0), map masses carry no information; "
           "non-object labels are only 'seen free -> navigable' (or ignore)")


def _overrides(args: argparse.Namespace) -> dict[str, Any]:
    """The ``kitti`` config overrides of the options, each checked by its flag (the
    config's own errors would name keys and values the user never typed)."""
    from dstenv.config import CLIError
    from dstenv.kitti.sequence import default_config

    out: dict[str, Any] = {"labels": {}}
    for key, low in (("stride", 1), ("warmup", 0), ("update_every", 1)):
        value = getattr(args, key, None)
        if value is not None:
            if value < low:
                raise CLIError(f"--{key.replace('_', '-')} must be >= {low}, got {value}")
            out[key] = value
    if hasattr(args, "stride"):  # convert (render keeps its --frame, checked there)
        d = default_config()
        every = out.get("update_every", d["update_every"])
        for key in ("stride", "warmup"):
            if out.get(key, d[key]) % every:
                given = "" if key in out else f" (the default: give --{key})"
                raise CLIError(f"--{key} {out.get(key, d[key])}{given} is no multiple of "
                               f"--update-every {every}: kept frames must be filtered frames")
    if args.label_rule is not None:
        out["labels"]["rule"] = args.label_rule
    if args.free_label is not None:
        out["labels"]["free_label"] = args.free_label
    if args.dst_preset is not None:
        from dstenv.dst import DSTParams

        out["dst"] = DSTParams.preset(args.dst_preset).to_dict()
    return out


def _gis(args: argparse.Namespace, seq: Any):
    """``(gis_fn, note)``: the map lookup for a sequence, or ``None`` and the no-map note."""
    if not args.osm:
        return None, _NO_MAP
    from dstenv.kitti.osm import map_lookup

    fn, note = map_lookup(args.osm, seq.trajectory)
    return fn, note


def _sequences(text: str) -> list[str]:
    """``"3,0005"`` -> ``["0003", "0005"]``: KITTI's 4-digit names, each once."""
    names = []
    for word in (s.strip() for s in text.split(",")):
        if not word:
            continue
        if not word.isdigit() or len(word) > 4:
            raise argparse.ArgumentTypeError(f"{word!r} is not a sequence number like 0003")
        name = f"{int(word):04d}"
        if name in names:
            raise argparse.ArgumentTypeError(f"sequence {name} listed twice")
        names.append(name)
    if not names:
        raise argparse.ArgumentTypeError("expected a comma-separated list like 0003,0005")
    return names


def _split_name(text: str) -> str:
    """A split is a plain name (a folder of ``--out``), never a path."""
    if not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9_-]{0,63}", text):
        raise argparse.ArgumentTypeError(
            f"{text!r}: a split is a plain name such as test or val (letters, digits, _ and -)")
    return text


def _same_conversion(path: Path, attrs: dict[str, Any], masses: bool) -> None:
    """Refuse to replace a converted shard made with other settings (the same command
    again rewrites the same bytes)."""
    from dstenv.config import CLIError, leaf_diffs
    from dstenv.data.shards import ShardError, ShardReader

    if not path.exists():
        return
    try:
        with ShardReader(path) as r:
            old = {k: r.attrs.get(k) for k in attrs} | {"masses": bool(r.attrs.get("has_masses"))}
    except ShardError:
        return  # a damaged shard of ours: converted again
    new = json.loads(json.dumps({**attrs, "masses": bool(masses)}))  # as stored
    diff = leaf_diffs(old, new)
    if diff:
        said = "; ".join(f"{k}: {a!r}, now {b!r}" for k, a, b in diff[:3])
        raise CLIError(f"{path} was converted with other settings ({said}"
                       + (f"; {len(diff) - 3} more" if len(diff) > 3 else "")
                       + "); use another --out or remove it")


def _convert(args: argparse.Namespace) -> int:
    from dstenv.config import CLIError
    from dstenv.data.lock import DatasetLocked, dataset_lock
    from dstenv.data.manifest import MANIFEST_NAME, scan_shards, write_manifest
    from dstenv.kitti.sequence import KittiSequence, kitti_config

    from dstenv.io import made_folders, output_folder, remove_made

    try:  # never into the KITTI root it reads, another dataset, or a results folder
        out = output_folder(args.out, "--out", dataset=True, inputs=(("--root", args.root),))
    except ValueError as exc:
        raise CLIError(str(exc)) from None
    cfg = kitti_config(_overrides(args))
    targets = {out / args.split / f"kitti-{int(s):04d}.h5" for s in args.sequences
               if s.isdigit()}
    foreign = [p for p in scan_shards(out) if p not in targets] if out.is_dir() else []
    if foreign:
        raise CLIError(f"{out}: holds other shards ({foreign[0].relative_to(out)}); "
                       "choose an empty output directory")
    # every sequence (and its map) is read, and every check made, before anything is
    # written; the old manifest goes first and the new one comes last, so a run that
    # dies half-way leaves a folder that readers refuse until the command is rerun
    seqs = [KittiSequence(args.root, name) for name in args.sequences]
    maps = [_gis(args, seq) for seq in seqs]
    plans = []
    for seq in seqs:
        path = out / args.split / f"kitti-{seq.name}.h5"
        attrs = {
            "config": cfg, "seed": int(seq.name), "split": args.split, "source": "kitti",
            "sequence": seq.name, "root": str(Path(args.root).resolve()),
            "map": str(Path(args.osm).resolve()) if args.osm else "none",
        }
        if cfg["warmup"] >= seq.n_frames:
            raise CLIError(f"sequence {seq.name}: --warmup {cfg['warmup']} is past its "
                           f"{seq.n_frames} frames")
        _same_conversion(path, attrs, args.masses)
        plans.append((path, attrs))
    made = made_folders(out)
    try:
        with dataset_lock(out):
            (out / MANIFEST_NAME).unlink(missing_ok=True)
            entries = [_write_sequence(seq, cfg, gis_fn, note, path, attrs, args.masses, out)
                       for seq, (gis_fn, note), (path, attrs) in zip(seqs, maps, plans,
                                                                     strict=True)]
            meta = {"command": "kitti convert", "root": str(Path(args.root).resolve()),
                    "sequences": args.sequences, "osm": args.osm or None, "config": cfg}
            write_manifest(out, entries, meta)
    except DatasetLocked as exc:
        raise CLIError(f"{out}: another run writes into it ({exc}); wait for it or use "
                       "another --out") from None
    except CLIError:
        remove_made(out, made)  # nothing written: no empty folders left behind
        raise
    print(f"wrote {out / MANIFEST_NAME}")
    return 0


def _write_sequence(seq: Any, cfg: dict[str, Any], gis_fn: Any, note: str, path: Path,
                    attrs: dict[str, Any], masses: bool, out: Path) -> dict[str, Any]:
    """Convert one sequence into its shard; returns its manifest entry."""
    from dstenv.config import CLIError
    from dstenv.data.manifest import shard_entry
    from dstenv.data.shards import ShardWriter
    from dstenv.dst import CLASSES
    from dstenv.kitti.sequence import convert_sequence, skip_reason

    print(f"sequence {seq.name}: {seq.n_frames} frames, DST every {cfg['update_every']}, "
          f"keep every {cfg['stride']} from {cfg['warmup']}, labels {cfg['labels']['rule']}; "
          f"{note}")
    skipped: list[str] = []
    made = not path.parent.exists()
    try:
        with ShardWriter(path, attrs, masses=masses) as writer:
            for frame in convert_sequence(seq, cfg, gis_fn, skipped):
                writer.add(frame)
            if writer.n_frames == 0:
                first = (skip_reason(skipped[0]) if skipped
                         else "no frame is kept")
                raise CLIError(f"sequence {seq.name}: no usable frame ({len(skipped)} "
                               f"skipped; the first: {first}); fix its files or leave it "
                               "out of --sequences")
    except CLIError:
        if made and path.parent.is_dir() and not any(path.parent.iterdir()):
            path.parent.rmdir()  # the split folder this run made, left empty
        raise
    for msg in [*seq.notes, *skipped]:
        print(f"  warning: {msg}")
    entry = shard_entry(out, path)
    counts = dict(zip(CLASSES, entry["class_counts"], strict=True))
    if not sum(counts.values()):  # not even the ground it saw: a broken pose or calibration
        path.unlink()
        raise CLIError(f"sequence {seq.name}: no labelled cell in {writer.n_frames} frames; "
                       "check its calib (Tr_velo_cam) and oxts files")
    print(f"  wrote {path} ({writer.n_frames} frames; labelled cells: "
          + ", ".join(f"{k} {v}" for k, v in counts.items()) + ")")
    return entry


def _render(args: argparse.Namespace) -> int:
    from dstenv.config import CLIError
    from dstenv.grid import GridSpec
    from dstenv.io import png_path
    from dstenv.kitti.render import render_frame
    from dstenv.kitti.sequence import KittiSequence, convert_sequence, kitti_config, skip_reason

    png_path(args.out)  # before the conversion, not after (under --root is fine)
    over = _overrides(args)
    every = over.get("update_every", 1)
    if args.frame < 0:
        raise CLIError(f"--frame must be a frame number >= 0, got {args.frame}")
    if args.frame % every:
        raise CLIError(f"--frame {args.frame}: the filter runs every {every} frames; "
                       f"pick a multiple of {every}")
    over.update(warmup=args.frame, stride=every * 10**6)  # keep exactly this frame
    cfg = kitti_config(over)
    seq = KittiSequence(args.root, args.sequence)
    if args.frame >= seq.n_frames:  # before converting the frames up to it
        raise CLIError(f"--frame {args.frame}: sequence {seq.name} has {seq.n_frames} frames "
                       f"(0 .. {seq.n_frames - 1})")
    gis_fn, note = _gis(args, seq)
    frame = None
    skipped: list[str] = []
    for fr in convert_sequence(seq, cfg, gis_fn, skipped):
        if fr.step == args.frame:
            frame = fr
            break
    if frame is None:
        why = next((skip_reason(m) for m in skipped
                    if m.startswith(f"sequence {seq.name} frame {args.frame}: ")), None)
        raise CLIError(f"sequence {seq.name}: frame {args.frame} was skipped: {why}" if why
                       else f"sequence {seq.name}: frame {args.frame} was not converted")
    boxes = seq.boxes.select(seq.boxes.frame == args.frame)
    where = f"map: {args.osm}" if args.osm else "no map"
    title = (f"KITTI tracking {seq.name} frame {args.frame} (DST every {every} scan(s), "
             f"{cfg['labels']['rule']} motion rule); {where}")
    spec = GridSpec(**cfg["grid"])
    path = render_frame(frame, boxes, spec, args.out, title, seq.scan(args.frame))
    for msg in skipped:  # scans of the filter's history before this frame (as convert)
        print(f"  warning: {msg}")
    print(f"{note}\nwrote {path}")
    return 0


def _evaluate(args: argparse.Namespace) -> int:
    """An alias of ``dstenv benchmark --data DIR``: the same scoring and report."""
    import shutil
    import tempfile

    from dstenv.config import CLIError
    from dstenv.io import atomic_write_bytes, output_file
    from dstenv.segment.bench_cli import run_cli_benchmark

    if args.batch_size < 1:
        raise CLIError(f"--batch-size must be >= 1, got {args.batch_size}")
    for flag, value in (("--out", args.out), ("--json", args.json)):
        if value is not None and not value.strip():  # an unset variable, not "no --out"
            raise CLIError(f"{flag}: empty; leave it out or give a path")
    if args.json:
        output_file(args.json, "--json")  # before the scoring, not after
    tmp = None if args.out else tempfile.mkdtemp(prefix="dstenv-kitti-eval-")
    bench = argparse.Namespace(
        preset=None, protocol=None, out=args.out or tmp, data=args.data,
        checkpoint=args.checkpoint, quiet=True, show_report=True,
        set=[f"eval_batch_size={args.batch_size}", "device=\"cpu\"", *(args.set or [])],
    )
    try:
        try:
            run_cli_benchmark(bench, split=args.split, kept=tmp is None)
        except OSError as exc:  # (it named a scratch file that was then deleted)
            if tmp is None:
                raise
            raise CLIError(f"the report's scratch folder {tmp} (removed) could not be "
                           f"written ({exc.strerror or exc}); give --out DIR on a disk with "
                           "room") from None
        if args.json:  # atomically: a full disk left a cut JSON in place of the old one
            try:
                atomic_write_bytes(args.json, (Path(bench.out) / "results.json").read_bytes())
            except OSError as exc:
                raise CLIError(f"--json {args.json}: cannot write it ({exc.strerror or exc}); "
                               "the file there is unchanged") from None
            print(f"wrote {args.json}")
    finally:
        if tmp:
            shutil.rmtree(tmp, ignore_errors=True)
    return 0


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument("--root", required=True, metavar="DIR",
                   help="KITTI tracking folder (holding training/ or velodyne/)")
    p.add_argument("--osm", metavar="FILE",
                   help="OpenStreetMap .osm of the drive area for the GIS grid (default: no map)")
    p.add_argument("--update-every", type=int, metavar="K",
                   help="run the DST filter on every K-th scan (default 1: 10 Hz)")
    p.add_argument("--label-rule", choices=("paper", "smoothed"),
                   help="moving rule: 10 cm frame to frame (paper) or a fitted speed (default)")
    p.add_argument("--free-label", choices=("navigable", "ignore"),
                   help="label of seen-free cells without a map class (default navigable)")
    p.add_argument("--dst-preset", choices=("default", "paper"), help="DST parameters")


def _export(args: argparse.Namespace) -> int:
    from dstenv.config import CLIError
    from dstenv.data.sampling import scenario_config
    from dstenv.kitti.export import export_drive

    if args.frames < 1:
        raise CLIError(f"--frames must be >= 1, got {args.frames}")
    if not 0 <= args.seed < 2**63:  # as render and generate (a larger one wrapped around)
        raise CLIError(f"--seed must be in [0, 2**63), got {args.seed}")
    from dstenv.io import output_folder

    try:  # a KITTI root of its own: never inside a dataset
        output_folder(args.out, "--out")
    except ValueError as exc:
        raise CLIError(str(exc).replace("give a folder", "give a folder for the KITTI root",
                                        1)) from None
    try:
        split = export_drive(scenario_config(args.scenario), args.seed, args.frames, args.out,
                             args.sequence)
    except (ValueError, FileExistsError) as exc:
        raise CLIError(str(exc).removeprefix("export-kitti: ")) from None
    print(f"wrote {args.frames} frames of sequence {args.sequence:04d} under {split}; "
          f"read it back with: dstenv kitti convert --root {args.out} "
          f"--sequences {args.sequence:04d} --out DIR")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``dstenv kitti convert|render|evaluate`` and ``dstenv export-kitti`` to the CLI."""
    from dstenv.cli import plain

    x = sub.add_parser("export-kitti", help="simulate a drive with the 3-D LIDAR, write it "
                       "in KITTI tracking format", description=(
                           "Simulated drive -> velodyne/SSSS/*.bin, label_02, oxts, calib "
                           "(dstenv.kitti.export)"))
    x.add_argument("--scenario", metavar="NAME|FILE", help="scenario (default: the defaults)")
    x.add_argument("--frames", type=int, required=True, help="frames to simulate (10 Hz)")
    x.add_argument("--seed", type=int, default=0, help="episode seed (default 0)")
    x.add_argument("--sequence", type=int, default=0, help="sequence number SSSS (default 0)")
    x.add_argument("--out", required=True, metavar="DIR", help="dataset folder (gets training/)")
    x.set_defaults(func=_export)
    k = sub.add_parser("kitti", help="KITTI tracking -> perception-grid shards",
                       description=plain(__doc__),
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    ksub = k.add_subparsers(dest="kitti_command", metavar="ACTION", required=True)
    c = ksub.add_parser("convert", help="convert sequences to shards + manifest")
    _common(c)
    c.add_argument("--sequences", required=True, type=_sequences, metavar="LIST",
                   help="comma-separated sequence numbers, e.g. 0003,0005")
    c.add_argument("--stride", type=int, metavar="K",
                   help="keep one frame every K scans (default 5 = 0.5 s; the paper: 10-20)")
    c.add_argument("--warmup", type=int, metavar="K", help="first kept frame (default 5)")
    c.add_argument("--split", default="test", type=_split_name,
                   help="split name stored in the shards (default test)")
    c.add_argument("--masses", action="store_true", help="also store the raw 32 DST masses")
    c.add_argument("--out", required=True, metavar="DIR", help="output dataset directory")
    c.set_defaults(func=_convert)
    r = ksub.add_parser("render", help="PNG of one raw KITTI frame (--root): scan, grids, labels")
    _common(r)
    r.add_argument("--sequence", required=True, help="sequence number, e.g. 0003")
    r.add_argument("--frame", type=int, required=True, help="frame index to render")
    r.add_argument("--out", required=True, metavar="PNG")
    r.set_defaults(func=_render)
    e = ksub.add_parser("evaluate", help="score DST and trained checkpoints on converted shards")
    e.add_argument("--data", required=True, metavar="DIR", help="output of kitti convert")
    e.add_argument("--checkpoint", action="append", default=[], metavar="PT",
                   help="a checkpoint of dstenv train (repeatable)")
    e.add_argument("--batch-size", type=int, default=4)
    e.add_argument("--split", default="test", help="split to score (default test)")
    e.add_argument("--out", metavar="DIR", help="keep the benchmark report here")
    e.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help="benchmark option, e.g. tune.params=@results.json (repeatable)")
    e.add_argument("--json", metavar="FILE", help="also write results.json here")
    e.set_defaults(func=_evaluate)
    logging.getLogger("dstenv.kitti").addHandler(logging.NullHandler())
