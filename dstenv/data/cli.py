"""``dstenv generate`` and ``dstenv info``: make a shard dataset and describe one."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

__all__ = ["register", "parse_set", "summarize"]

#: Class shares of the paper's KITTI training set (Itkina & Kochenderfer, Sec. 4).
PAPER_FREQUENCIES = {"static": 0.0009, "moving": 0.0026}


def parse_set(items: list[str]) -> dict[str, Any]:
    """``["world.n_cars=10", "lidar.fov=180.0"]`` -> nested overrides (TOML values; a
    value that is no TOML but a JSON object or array, as ``results.json`` prints them,
    is read as JSON; anything else is a string).

    Raises:
        CLIError: an item without ``=``, an empty key, or an item below a value that an
            earlier item set (``world=5`` then ``world.traffic.cars=3``).
    """
    from dstenv.config import CLIError

    out: dict[str, Any] = {}
    where: dict[tuple[str, ...], str] = {}  # the item that set each value
    for item in items:
        key, sep, text = item.partition("=")
        parts = key.strip().split(".")
        if not sep or not all(parts):
            raise CLIError(f"--set {item!r}: expected SECTION.KEY=VALUE")
        try:
            value = tomllib.loads(f"v = {text}")["v"]
        except tomllib.TOMLDecodeError:
            value = _json_or_word(text)
        node = out
        for i, p in enumerate(parts[:-1]):
            node = node.setdefault(p, {})
            if not isinstance(node, dict):
                by = next(where[tuple(parts[:j])] for j in range(i + 1, 0, -1)
                          if tuple(parts[:j]) in where)
                raise CLIError(f"--set {item!r}: {'.'.join(parts[:i + 1])} is already set to "
                               f"a value by --set {by!r}; give one")
        node[parts[-1]] = value
        where[tuple(parts)] = item
    return out


def _json_or_word(text: str) -> Any:
    """A JSON object or array, else the text itself (a bare word is a string)."""
    if text.lstrip().startswith(("{", "[")):
        try:
            return json.loads(text)
        except json.JSONDecodeError:
            pass
    return text


def _grid(text: str) -> tuple[int, int]:
    h, sep, w = text.lower().partition("x")
    try:
        if sep and not w:  # "64x": a width left out, not a square grid
            raise ValueError
        size = (int(h), int(w or h))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected N or HxW cells, got {text!r}") from None
    if min(size) < 2:
        raise argparse.ArgumentTypeError(f"grid must be at least 2x2 cells, got {text!r}")
    return size


def _generate(args: argparse.Namespace) -> int:
    from dstenv.config import CLIError, build_config
    from dstenv.data.generate import GenerateError, GenerateSpec, generate

    from dstenv.io import output_folder

    try:  # never inside another dataset, nor into a training run's or a report's folder
        output_folder(args.out, "--out", dataset=True)
    except ValueError as exc:
        raise CLIError(str(exc)) from None
    if args.compression == "none" and (args.gzip_level is not None or args.deflate):
        raise CLIError("--gzip-level and --deflate set the gzip compression; with "
                       "--compression none they would do nothing: leave them out")
    overrides = parse_set(args.set or [])
    grid = overrides.get("grid", {}) if isinstance(overrides.get("grid"), dict) else {}
    flags = {}
    if args.grid:
        flags["height"] = ("--grid", args.grid[0])
        flags["width"] = ("--grid", args.grid[1])
    if args.cell_size is not None:
        flags["cell_size"] = ("--cell-size", args.cell_size)
    for key, (flag, value) in flags.items():
        if key in grid and grid[key] != value:  # one of the two would be dropped unseen
            raise CLIError(f"{flag} and --set grid.{key}={grid[key]} disagree: give one")
    layers = [("--set", overrides)]  # a layer per source: an error names the one that wrote it
    if flags:
        layers.append(("/".join(dict.fromkeys(f for f, _ in flags.values())),
                       {"grid": {k: v for k, (_, v) in flags.items()}}))
    config = build_config(args.scenario, *layers)
    if config.get("world", {}).get("map", {}).get("kind") == "osm" and not args.quiet:
        print("dstenv generate: note: this scenario has one fixed OSM map; its splits differ "
              "in traffic and route, not in map", file=sys.stderr)
    try:
        spec = GenerateSpec(
            config=config, frames=args.frames, seed=args.seed,
            scenario=args.scenario or "(default config)",
            split=args.split, frames_per_shard=args.frames_per_shard,
            episode_length=args.episode_length, stride=args.stride,
            warmup=args.stride if args.warmup is None else args.warmup, masses=args.masses,
            episodes_per_map=args.episodes_per_map,
            quantize=not args.float32,
            compression=None if args.compression == "none" else args.compression,
            compression_level=1 if args.gzip_level is None else args.gzip_level,
            deflate=args.deflate or "isal",
        )
        if not args.quiet:  # once the options are known to be good
            from dstenv._jitcache import kernels_cached

            if not kernels_cached(Path(__file__).parents[1]):
                print("dstenv generate: note: first run of this install: compiling the numba "
                      "kernels first (about a minute, kept for later runs); the first "
                      "frames' time estimate includes it", file=sys.stderr)
        manifest = generate(spec, args.out, workers=args.workers, ray_address=args.ray,
                            progress=not args.quiet, force_unlock=args.force_unlock)
    except GenerateError as exc:
        raise CLIError(str(exc)) from None
    if not args.quiet:
        print(format_summary(summarize(Path(args.out), manifest)))
    return 0


def summarize(root: Path, manifest: dict[str, Any] | None = None, verify: str = "attrs"
              ) -> dict[str, Any]:
    """Facts about a dataset directory (or one shard file) for ``dstenv info``."""
    from dstenv.data.manifest import MANIFEST_NAME, build_manifest, load_manifest, shard_entry

    if root.is_file():
        manifest = build_manifest([shard_entry(root.parent, root)])
        source = "single shard"
        if verify in ("frames", "hash"):  # no manifest to compare with: read it whole
            _read_whole([root])
            source += ", every chunk read (checksums)"
    elif manifest is None and (root / MANIFEST_NAME).exists():
        manifest = load_manifest(root, verify=verify)
        source = str(root / MANIFEST_NAME)
    elif manifest is None:
        from dstenv.data.manifest import one_dataset, scan_shards

        if root.is_dir():
            one_dataset(root)
        shards = scan_shards(root)
        if not root.is_dir() or not shards:
            from dstenv.config import CLIError

            raise CLIError(f"{root}: no manifest.json and no shards (*.h5) found")
        manifest = build_manifest([shard_entry(root, p) for p in shards])
        source = "scanned shards (no manifest.json)"
        if verify in ("frames", "hash"):  # no hashes to compare with: read every chunk
            _read_whole(shards)
            source = "scanned shards (no manifest.json), every chunk read (checksums)"
    else:
        source = str(root / MANIFEST_NAME)
    try:  # --verify none reads the manifest as it stands
        size = sum(int(e["bytes"]) for e in manifest["shards"])
        frames = int(manifest["frames"])
        return {
            "path": str(root), "source": source, "frames": frames,
            "shards": len(manifest["shards"]), "bytes": size,
            "bytes_per_frame": size / max(frames, 1),
            "grid_shape": manifest["grid_shape"], "cell_size": float(manifest["cell_size"]),
            "splits": {k: {"frames": int(v["frames"]), "shards": int(v["shards"])}
                       for k, v in manifest["splits"].items()},
            "class_frequencies": {str(k): float(v)
                                  for k, v in manifest["class_frequencies"].items()},
        }
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        from dstenv.data.manifest import ManifestError

        raise ManifestError(f"{source}: a missing or malformed entry ({type(exc).__name__}: "
                            f"{exc}); check it with --verify attrs, or delete the manifest and "
                            "rerun the command that made the dataset") from None


def _read_whole(paths: list[Path]) -> None:
    """Read every chunk of each shard (its Fletcher-32 checksums): a corrupt one raises."""
    from dstenv.data.shards import ShardReader

    for path in paths:
        with ShardReader(path) as r:
            r.verify()


def format_summary(s: dict[str, Any]) -> str:
    """Human-readable text of :func:`summarize`."""
    h, w = s["grid_shape"]
    def n(count: int, what: str) -> str:
        return f"{count} {what}{'' if count == 1 else 's'}"

    splits = ", ".join(f"{k} {n(v['frames'], 'frame')} / {n(v['shards'], 'shard')}"
                       for k, v in s["splits"].items())
    lines = [
        f"dataset   {s['path']}  ({s['source']})",
        f"frames    {s['frames']} in {n(s['shards'], 'shard')}: {splits}",
        f"grid      {h} x {w} cells of {s['cell_size']:g} m",
        f"disk      {s['bytes'] / 2**20:.2f} MiB, {s['bytes_per_frame'] / 1024:.1f} KiB per frame",
        "class distribution (share of labelled cells)",
        f"  {'class':<15}{'ours':>10}{'paper (KITTI)':>16}",
    ]
    from dstenv.dst.frame import CLASSES

    freqs = s["class_frequencies"]  # JSON sorts keys: print in the classes' own order
    for name in sorted(freqs, key=lambda n: (CLASSES.index(n) if n in CLASSES else 99, n)):
        freq = freqs[name]
        paper = PAPER_FREQUENCIES.get(name)
        ref = f"{100 * paper:.2f}%" if paper is not None else "-"
        lines.append(f"  {name:<15}{100 * freq:>9.2f}%{ref:>16}")
    return "\n".join(lines)


def _info(args: argparse.Namespace) -> int:
    import json

    from dstenv.config import CLIError
    from dstenv.data.manifest import ManifestError
    from dstenv.data.shards import ShardError

    root = Path(args.path)
    if not root.exists():
        raise CLIError(f"{root}: no such file or directory")
    if root.is_file() and root.name == "manifest.json":  # the dataset it describes
        root = root.parent
    try:
        s = summarize(root, verify=args.verify)
    except (ManifestError, ShardError) as exc:
        raise CLIError(str(exc)) from None
    from dstenv.data.lock import writer_of
    from dstenv.io import PARTIAL_SUFFIX

    busy = writer_of(root) if root.is_dir() else None
    if busy:
        print(f"dstenv info: note: {root} is still being written by {busy}: these are the "
              "shards finished so far", file=sys.stderr)
    elif root.is_file() and root.name.endswith(PARTIAL_SUFFIX):
        print(f"dstenv info: note: {root} is a shard being written, or left by a run that "
              "was killed: not part of any dataset (a rerun of that run replaces it)",
              file=sys.stderr)
    elif root.is_dir() and s["source"].startswith("scanned shards"):
        print(f"dstenv info: note: {root} has no manifest.json: if a dstenv run made it, that "
              "run did not finish (these are the shards it wrote); rerun its command to "
              "complete it", file=sys.stderr)
    print(json.dumps(s, indent=1) if args.json else format_summary(s))
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``dstenv generate`` and ``dstenv info`` to the CLI."""
    p = sub.add_parser(
        "generate", help="generate labelled frames as HDF5 shards",
        description="Simulate autopilot episodes and write labelled perception-grid frames as "
                    "HDF5 shards plus manifest.json. Deterministic; rerun to resume.",
    )
    p.add_argument("--scenario", metavar="NAME|FILE", help="scenario name or .toml file "
                   "(default: the default configuration)")
    p.add_argument("--frames", type=int, required=True, help="total frames to generate")
    p.add_argument("--out", required=True, metavar="DIR", help="output directory")
    p.add_argument("--seed", type=int, default=0, help="base seed (default 0)")
    p.add_argument("--workers", type=int, default=1,
                   help="parallel worker processes (default 1: one core)")
    p.add_argument("--split", default="auto", choices=["auto", "train", "val", "test"],
                   help="auto: 80/10/10 train/val/test from disjoint map seeds (default)")
    p.add_argument("--episode-length", type=int, default=200,
                   help="steps per episode, 0.1 s each (default 200 = 20 s)")
    p.add_argument("--stride", type=int, default=10,
                   help="keep one frame every STRIDE steps (default 10 = 1 s)")
    p.add_argument("--warmup", type=int, default=None,
                   help="first kept step of an episode (default: STRIDE)")
    p.add_argument("--episodes-per-map", type=int, default=1, metavar="E",
                   help="episodes (new traffic and route) on each procedural city before "
                        "building the next; a city costs ~100 steps (default 1)")
    p.add_argument("--grid", type=_grid, metavar="N|HxW", help="grid size in cells")
    p.add_argument("--cell-size", type=float, help="cell size [m]")
    p.add_argument("--set", action="append", metavar="SECTION.KEY=VALUE",
                   help="override any config value (TOML value), repeatable")
    p.add_argument("--masses", action="store_true", help="also store the raw (32,H,W) masses")
    p.add_argument("--float32", action="store_true",
                   help="store probabilities as float32 (default uint8, error <= 1/510)")
    p.add_argument("--compression", default="gzip", choices=["gzip", "none"],
                   help="shard compression (default gzip; lzf is not offered: h5py's LZF "
                        "filter does not write the same bytes twice)")
    p.add_argument("--gzip-level", type=int, default=None, choices=range(10), metavar="0-9",
                   help="gzip level (default 1: ~46 KiB per 256x256 frame of the default "
                        "scenario with isal; higher levels shrink it a little at several "
                        "times the write time)")
    p.add_argument("--deflate", default=None, choices=["isal", "zlib"],
                   help="gzip engine: isal (default; its deflate ~5x faster than zlib's, the "
                        "whole write path ~2.6x less CPU) or zlib (h5py's own bytes); "
                        "both read back with plain h5py")
    p.add_argument("--frames-per-shard", type=int, default=256,
                   help="frames per shard file (default 256); shards are the unit of work "
                        "and of resume")
    p.add_argument("--ray", nargs="?", const="local", default=None, metavar="ADDRESS",
                   help="run shards as Ray tasks; no ADDRESS starts a local Ray")
    p.add_argument("--quiet", action="store_true", help="no progress bar or summary")
    p.add_argument("--force-unlock", action="store_true",
                   help="take over DIR/.dstenv.lock of a run that died on another host")
    p.set_defaults(func=_generate)

    q = sub.add_parser("info", help="describe a shard dataset",
                       description="Frames, shards, class distribution and disk use of a "
                                   "dataset directory or shard file.")
    q.add_argument("path", metavar="DIR|FILE")
    q.add_argument("--verify", default="attrs", choices=["none", "size", "attrs", "frames", "hash"],
                   help="how far to check: size (files and sizes), attrs (default: also each "
                        "shard's frames, class counts and settings), frames (also every "
                        "chunk's checksum), hash (also each file's SHA-256 against the manifest)")
    q.add_argument("--json", action="store_true", help="print JSON")
    q.set_defaults(func=_info)


if __name__ == "__main__":  # pragma: no cover
    from dstenv.cli import main

    sys.exit(main(["generate", *sys.argv[1:]]))
