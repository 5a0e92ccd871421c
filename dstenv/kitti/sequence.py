"""One KITTI tracking sequence -> labelled :class:`dstenv.frame.Frame` objects.

Flow per filtered scan (every ``update_every``-th, default all: 10 Hz): Velodyne
scan -> :func:`dstenv.sensing.cloud.cloud_sensor_grid` (ground removal, rays: the
road the simulated 3-D LIDAR takes too) + GIS grid (OSM map cut at the OXTS pose,
or vacuous) -> :class:`dstenv.dst.tracker.GridTracker` -> BetP. One
frame every ``stride`` scans from ``warmup`` on is kept, with labels from the boxes
of that frame (as ``dstenv generate --stride --warmup`` keeps simulator steps).

A frame whose scan is missing, truncated or has no ground is skipped with a logged
warning (the filter then moves straight from the previous used frame); anything
wrong with the sequence files themselves raises :class:`KittiError`.
"""

from __future__ import annotations

import logging
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from dstenv.config import ConfigError, merge_config
from dstenv.dst import DSTParams
from dstenv.dst.tracker import GridTracker
from dstenv.frame import Frame
from dstenv.grid import GridSpec
from dstenv.kitti.grids import FREE_LABELS, camera_fov, dontcare_cells, label_grid
from dstenv.kitti.objects import MOVING_RULES, boxes_in_velodyne, moving_flags, world_centres
from dstenv.kitti.poses import oxts_to_trajectory
from dstenv.kitti.readers import (
    KittiError,
    read_calib,
    read_labels,
    read_oxts,
    read_velodyne,
    split_root,
    velodyne_path,
)
from dstenv.sensing import visible_mask
from dstenv.sensing.cloud import cloud_sensor_grid, default_ray_config
from dstenv.sensing.ground import CloudError, default_ground_config

__all__ = [
    "SKIPPED", "skip_reason",
    "FRAME_RATE", "default_config", "kitti_config", "kept_frames",
    "KittiSequence", "convert_sequence",
]

log = logging.getLogger("dstenv.kitti")

#: KITTI tracking frames per second [Hz].
FRAME_RATE: float = 10.0


def default_config() -> dict[str, Any]:
    """Converter settings (units in comments); override with :func:`merge_config`."""
    return {
        "grid": {"height": 256, "width": 256, "cell_size": 0.33},  # the paper's geometry [m]
        # the filter runs on every `update_every`-th scan (1: 10 Hz, like the simulator's
        # 0.1 s step); one frame every `stride` scans is kept, from frame `warmup` on, as
        # `dstenv generate --stride --warmup` does. 5/5 keeps 7 frames of the 40-frame
        # sample; the paper kept one every 1-2 s (stride 10-20)
        "update_every": 1,  # [frames]
        "stride": 5,  # [frames]
        "warmup": 5,  # [frames] first kept frame (the filter has seen frames before it)
        # rays into the sensor grid: dstenv.sensing.cloud.default_ray_config
        "sensor": default_ray_config(),
        "ground": default_ground_config(),
        "labels": {
            "rule": "smoothed",  # "paper" (10 cm frame to frame) or "smoothed" (line fit)
            "threshold": 0.10,  # [m per 0.1 s frame] displacement above which a box moves
            "window": 5,  # [frames] half-width of the smoothed rule's fit
            "free_label": "navigable",  # seen-free cells without a map class: or "ignore"
            "image_width": 1242,  # [px] left camera width, bounds the labelled field of view
            "dontcare_dilation": 1,  # [cells] growth of DontCare regions
        },
        "dst": DSTParams.default().to_dict(),
    }


def kitti_config(config: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """:func:`default_config` merged with ``config`` and checked.

    Raises:
        ConfigError: an unknown key (named, with the allowed ones) or a bad value.
    """
    cfg = merge_config(default_config(), config, "kitti")
    lab = cfg["labels"]
    if lab["rule"] not in MOVING_RULES:
        raise ConfigError(
            f"kitti.labels.rule: {lab['rule']!r}; choose from {', '.join(MOVING_RULES)}"
        )
    if lab["free_label"] not in FREE_LABELS:
        raise ConfigError(
            f"kitti.labels.free_label: {lab['free_label']!r}; choose from {', '.join(FREE_LABELS)}"
        )
    for key in ("stride", "update_every"):
        if cfg[key] < 1:
            raise ConfigError(f"kitti.{key}: must be >= 1 frame, got {cfg[key]}")
    if cfg["warmup"] < 0:
        raise ConfigError(f"kitti.warmup: must be >= 0, got {cfg['warmup']}")
    if cfg["stride"] % cfg["update_every"] or cfg["warmup"] % cfg["update_every"]:
        raise ConfigError("kitti.stride and kitti.warmup must be multiples of kitti.update_every "
                          f"({cfg['update_every']}): kept frames must be filtered frames")
    for key in ("max_range", "azimuth_bin_deg"):
        if not cfg["sensor"][key] > 0:
            raise ConfigError(f"kitti.sensor.{key}: must be > 0, got {cfg['sensor'][key]}")
    if not cfg["sensor"]["block_window_deg"] >= 0:
        raise ConfigError("kitti.sensor.block_window_deg: must be >= 0, got "
                          f"{cfg['sensor']['block_window_deg']}")
    try:
        DSTParams.from_dict(cfg["dst"])
        GridSpec(**cfg["grid"])
    except (ValueError, TypeError) as exc:
        raise ConfigError(f"kitti: {exc}") from None
    return cfg


def kept_frames(n_frames: int, config: Mapping[str, Any]) -> list[int]:
    """Frame indices a conversion keeps: ``warmup, warmup + stride, ...`` below ``n_frames``."""
    return list(range(config["warmup"], n_frames, config["stride"]))


class KittiSequence:
    """The files of one sequence, read and checked up front (scans on demand).

    Args:
        root: dataset folder (holding ``training/``) or the ``training`` folder.
        sequence: sequence name, e.g. ``"0003"`` (``3`` is padded).

    Attributes:
        name: the 4-digit sequence name.
        calib, trajectory, labels, boxes, world_xy: parsed files (see the readers).
        n_frames: number of OXTS rows (frames with a pose).
        notes: what the files leave out (scans past the OXTS rows, an empty label file).

    Raises:
        KittiError: a missing or malformed sequence file, or labels for frames
            that have no OXTS pose.
    """

    def __init__(self, root: str | Path, sequence: str | int) -> None:
        self.split = split_root(root)
        name = str(sequence).strip()
        if not name.isdigit():
            raise KittiError(f"sequence {sequence!r} is not a number like 0003")
        self.name = f"{int(name):04d}"
        if not (self.split / "velodyne" / self.name).is_dir():
            have = sorted(d.name for d in (self.split / "velodyne").iterdir()
                          if d.is_dir() and d.name.isdigit())
            listed = ", ".join(have[:20]) + (" ..." if len(have) > 20 else "")
            raise KittiError(f"{self.split / 'velodyne' / self.name}: missing scan folder "
                             f"(sequences there: {listed or 'none'})")
        self.calib = read_calib(self.split / "calib" / f"{self.name}.txt")
        oxts = read_oxts(self.split / "oxts" / f"{self.name}.txt")
        self.trajectory = oxts_to_trajectory(oxts, self.calib.Tr_imu_velo)
        self.n_frames = len(oxts)
        label_path = self.split / "label_02" / f"{self.name}.txt"
        if not label_path.is_file() and self.split.name == "testing":
            raise KittiError(f"{label_path}: missing; KITTI's testing split has no labels "
                             "(point --root at the training split)")
        self.labels = read_labels(label_path)
        if len(self.labels) and self.labels.frame.max() >= self.n_frames:
            raise KittiError(
                f"{label_path}: labels for frame {int(self.labels.frame.max())} but the OXTS "
                f"file has only {self.n_frames} frames"
            )
        self.boxes = boxes_in_velodyne(self.labels, self.calib)
        self.world_xy = world_centres(self.boxes, self.trajectory)
        #: what the files leave out, for the user (scans without a pose, no label at all)
        self.notes: list[str] = []
        scans = sum(1 for p in (self.split / "velodyne" / self.name).glob("*.bin")
                    if p.stem.isdigit() and int(p.stem) >= self.n_frames)
        if scans:
            self.notes.append(f"sequence {self.name}: {scans} scans past the OXTS file's "
                              f"{self.n_frames} rows have no pose and are not used")
        if not len(self.labels):
            self.notes.append(f"{label_path}: no object labelled in any frame")

    def scan_path(self, frame: int) -> Path:
        """Path of one frame's Velodyne scan."""
        return velodyne_path(self.split, self.name, frame)

    def scan(self, frame: int) -> np.ndarray:
        """``(P, 4) float32`` Velodyne points of one frame (raises :class:`KittiError`)."""
        return read_velodyne(self.scan_path(frame))

    def moving(
        self, rule: str = "smoothed", threshold: float = 0.10, window: int = 5
    ) -> np.ndarray:
        """``(K,) bool`` moving flag of every box (see :func:`moving_flags`)."""
        return moving_flags(self.boxes, self.world_xy, rule, threshold, window)


#: what joins a skipped frame's name and its reason in ``convert_sequence``'s messages
SKIPPED = ": skipped: "


def skip_reason(message: str) -> str:
    """The reason of a ``convert_sequence`` skip message (its file and what is wrong)."""
    return message.split(SKIPPED, 1)[-1]


def convert_sequence(
    seq: KittiSequence,
    config: Mapping[str, Any] | None = None,
    gis_fn: Any = None,
    skipped: list[str] | None = None,
) -> Iterator[Frame]:
    """Yield the labelled frames of one sequence.

    Args:
        seq: the sequence.
        config: overrides of :func:`default_config`.
        gis_fn: ``gis_fn(pose (3,), spec) -> (H, W) uint8`` GIS grid at a KITTI world
            pose, or ``None`` for a vacuous map (all 0: no information).
        skipped: if given, one message per skipped frame is appended.

    Yields:
        :class:`dstenv.frame.Frame` per kept frame (:func:`kept_frames`), with
        ``step`` = KITTI frame index, ``time`` = frame / 10 Hz, ``seed`` = the
        sequence number, ``masses`` the raw grid and ``extras["plane"]`` the
        ``(4,)`` ground plane of the scan.
    """
    cfg = kitti_config(config)
    spec = GridSpec(**cfg["grid"])
    lab = cfg["labels"]
    tracker = GridTracker(spec.shape, DSTParams.from_dict(cfg["dst"]), spec.cell_size)
    moving = seq.moving(lab["rule"], lab["threshold"], lab["window"])
    fov = camera_fov(seq.calib, spec, lab["image_width"])
    dontcare_boxes = seq.labels.select(seq.labels.is_dontcare)
    keep = set(kept_frames(seq.n_frames, cfg))
    for f in range(0, seq.n_frames, cfg["update_every"]):
        try:
            points = seq.scan(f)
            sensor, plane, _, obstacle, _ = cloud_sensor_grid(
                points, spec, cfg["ground"], cfg["sensor"])
        except (KittiError, CloudError) as exc:
            msg = f"sequence {seq.name} frame {f}{SKIPPED}{exc}"
            log.warning(msg)
            if skipped is not None:
                skipped.append(msg)
            continue
        pose = seq.trajectory.poses[f]
        gis = np.zeros(spec.shape, np.uint8) if gis_fn is None else gis_fn(pose, spec)
        out = tracker.step(sensor, gis, pose, masses=f in keep)
        if f in keep:
            sel = seq.boxes.frame == f
            dc = dontcare_cells(
                points, obstacle, dontcare_boxes.bbox[dontcare_boxes.frame == f], seq.calib,
                spec, lab["dontcare_dilation"],
            )
            labels = label_grid(
                seq.boxes.select(sel), moving[sel], sensor, fov, dc, spec,
                gis if gis_fn is not None else None, lab["free_label"],
            )
            yield Frame(
                pignistic=out.betp,
                pignistic_prev=out.betp_prev,
                labels=labels,
                visible=visible_mask(sensor),
                sensor=sensor,
                gis=gis,
                ego_pose=pose.copy(),
                time=f / FRAME_RATE,
                seed=int(seq.name),
                step=f,
                masses=out.masses,
                extras={"plane": plane},
            )
