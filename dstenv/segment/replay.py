"""Re-running the DST filter with other parameters on the same drives.

A stored frame holds BetP computed with the parameters used at generation time.
To score ``dst`` with another preset, or to tune the parameters, the filter must
run again from the raw inputs of *every* step of the episode up to the scored
frame (the accumulator and the past grid depend on all of them). We do it
honestly in two stages:

1. :func:`record_episodes` replays each episode once with
   :class:`dstenv.pipeline.Pipeline` (same configuration and episode seed as the
   shard, so the same world, LIDAR sweeps and labels) and keeps only the raw
   inputs of every step -- sensor grid, GIS grid, ego pose -- plus labels and
   ``visible`` at the scored steps: an :class:`Episode`.
2. :func:`filter_episode` runs a fresh :class:`dstenv.dst.tracker.GridTracker`
   with any :class:`~dstenv.dst.DSTParams` over those inputs, which costs only the
   filter, not the simulation, per parameter set.

:func:`check_replay` compares the replay with the generation parameters against
the stored BetP, so a replay that drifted from the stored data raises instead of
scoring different frames. :mod:`dstenv.segment.shardindex` finds the episodes and
stored frames of a shard split.

Evaluation-only datasets (KITTI conversions, or simulated shards without a train
split) cannot be replayed through the simulator.
:func:`dstenv.segment.shardindex.stored_episodes` rebuilds their :class:`Episode`
objects from the stored per-frame ``sensor``, ``gis`` and
``ego_pose`` instead -- honestly only when the shards hold *every* filtered step
from the first one on (otherwise the filter state between two stored frames is
lost, and it says so).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from dstenv.dst.params import DSTParams

__all__ = [
    "Episode",
    "filter_episode",
    "record_episodes",
    "check_replay",
    "filter_period",
    "generation_params",
    "SCHEDULE_KEYS",
]


@dataclass
class Episode:
    """Raw inputs of one drive and its labels at the scored steps.

    Attributes:
        seed: the map seed of the drive.
        sensor: ``(T, H, W) uint8`` sensor grid at every step 0..T-1.
        gis: ``(T, H, W) uint8`` GIS grid at every step.
        poses: ``(T, 3) float64`` ego pose the filter was given at every step (the
            true pose unless ``protocol.odometry_*`` adds an INS's errors).
        steps: ``(K,) int64`` scored steps, increasing, each < T.
        labels: ``(K, H, W) uint8`` labels at the scored steps.
        visible: ``(K, H, W) bool`` visible cells at the scored steps.
        cell_size: grid cell size [m].
        episode: index of the episode on its map (``episodes_per_map > 1`` drives one
            map several times, :mod:`dstenv.data.sampling`); a frame's key is
            ``(seed, episode, step)``.
        stored_x: optional ``(K, 10, H, W) float32`` stored BetP t / t-1 at the scored
            steps (what the networks were trained on); ``None``: recompute it.
        history: ``True`` when ``sensor``/``gis``/``poses`` hold every filtered step
            from the first one on, so the filter can be re-run with other parameters
            and the observed cells accumulated; ``False`` for stored frames only
            (then ``stored_x`` is required and ``steps = arange(K)``).
        period: the filter fuses steps ``0, period, 2 period, ...`` only (the paper's
            1 Hz fusion: ``dst.update_every``); t-1 is then the previous fused grid.
            Scored steps must be fused steps.
        stored_steps: optional ``(K,) int64`` step numbers of the scored frames in
            their source when ``steps`` index stored frames instead (``None``: the
            same as ``steps``).
        row_steps: optional ``(T,) int64`` step number of every row of ``sensor``,
            ``gis`` and ``poses`` in the source (``None``: the row index), which
            :func:`dstenv.segment.score.past_grids` needs for stored frames.
    """

    seed: int
    sensor: np.ndarray
    gis: np.ndarray
    poses: np.ndarray
    steps: np.ndarray
    labels: np.ndarray
    visible: np.ndarray
    cell_size: float
    episode: int = 0
    stored_x: np.ndarray | None = None
    history: bool = True
    period: int = 1
    stored_steps: np.ndarray | None = None
    row_steps: np.ndarray | None = None

    @property
    def key(self) -> tuple[int, int]:
        """``(seed, episode)``: identifies the drive among those of a split."""
        return (self.seed, self.episode)

    def frame_key(self, k: int) -> tuple[int, int, int]:
        """``(seed, episode, step)`` of scored frame ``k`` (its step in the source)."""
        steps = self.steps if self.stored_steps is None else self.stored_steps
        return (self.seed, self.episode, int(steps[k]))

    def __post_init__(self) -> None:
        t = self.sensor.shape[0]
        if self.gis.shape != self.sensor.shape or self.poses.shape != (t, 3):
            raise ValueError(
                f"episode {self.seed}: sensor {self.sensor.shape}, gis {self.gis.shape}, "
                f"poses {self.poses.shape} disagree"
            )
        if len(self.steps) and (
            np.any(np.diff(self.steps) <= 0) or self.steps[-1] >= t or self.steps[0] < 0
        ):
            raise ValueError(f"episode {self.seed}: scored steps must increase within [0, {t})")
        if self.labels.shape[0] != len(self.steps) or self.visible.shape != self.labels.shape:
            raise ValueError(
                f"episode {self.seed}: {len(self.steps)} steps but labels {self.labels.shape}"
            )
        if self.period < 1 or (self.history and np.any(self.steps % self.period)):
            raise ValueError(
                f"episode {self.key}: scored steps must be multiples of the fusion period "
                f"{self.period}"
            )
        if not self.history and self.stored_x is None:
            raise ValueError(f"episode {self.key}: stored frames only need stored_x")


def filter_episode(episode: Episode, params: DSTParams) -> np.ndarray:
    """Run the DST filter over an episode.

    The filter fuses every ``episode.period``-th step (the motion is taken from the
    previous fused pose), and t-1 is the previous fused grid.

    Returns:
        ``(K, 10, H, W) float32``: BetP at each scored step t and at t-1 (BetP at t
        again on the first fused step), the layout of :meth:`dstenv.frame.Frame.fcn_input`.
    """
    from dstenv.dst.tracker import GridTracker

    h, w = episode.sensor.shape[1:]
    tracker = GridTracker((h, w), params, cell_size=episode.cell_size)
    out = np.empty((len(episode.steps), 10, h, w), dtype=np.float32)
    wanted = {int(s): k for k, s in enumerate(episode.steps)}
    last = int(episode.steps[-1]) if len(episode.steps) else -1
    for t in range(0, last + 1, episode.period):  # the fused steps only
        step = tracker.step(episode.sensor[t], episode.gis[t], episode.poses[t])
        if t in wanted:
            out[wanted[t], :5] = step.betp
            out[wanted[t], 5:] = step.betp_prev
    return out


def record_episodes(
    config: Mapping[str, Any],
    targets: Mapping[tuple[int, int], Sequence[int]],
    progress: bool = False,
) -> list[Episode]:
    """Replay episodes with :class:`dstenv.pipeline.Pipeline` and keep their raw inputs.

    Episode ``k >= 1`` of a map drives the map of ``Pipeline.reset(seed)`` again with
    traffic from :func:`dstenv.data.sampling.traffic_seed` ``(seed, k)``, as
    :func:`dstenv.data.sampling.iter_frames` generated it.

    Args:
        config: the full pipeline configuration the shards were generated with
            (their ``config`` attribute).
        targets: ``(map seed, episode)`` -> steps to score (labels and ``visible`` are
            kept there).
        progress: show a tqdm bar.

    Returns:
        One :class:`Episode` per target, in ``sorted(targets)`` order.
    """
    from tqdm import tqdm

    from dstenv.data.sampling import traffic_seed
    from dstenv.pipeline import Pipeline
    from dstenv.sim.world import World

    pipe = Pipeline(dict(config))
    episodes = []
    for seed, k in tqdm(sorted(targets), desc="replay episodes", disable=not progress,
                        leave=False):
        steps = np.array(sorted(set(int(s) for s in targets[seed, k])), dtype=np.int64)
        frames = [pipe.reset(seed=int(seed))]
        if k > 0:  # same map, new traffic (dstenv.data.sampling.iter_frames)
            world = World(pipe.config["world"], 0, world_map=pipe.world.map)
            run = Pipeline(pipe.config, world=world)
            frames = [run.reset(traffic_seed(seed, k))]
        else:
            run = pipe
        # the pose the filter was given (protocol.odometry_*), on the fused steps
        poses = [run.filter_pose]
        while len(frames) <= steps[-1]:
            frames.append(run.step())
            poses.append(run.filter_pose if run.fused_step else frames[-1].ego_pose)
        episodes.append(
            Episode(
                seed=int(seed),
                episode=int(k),
                sensor=np.stack([f.sensor for f in frames]),
                gis=np.stack([f.gis for f in frames]),
                poses=np.stack([np.asarray(p, dtype=np.float64) for p in poses]),
                steps=steps,
                labels=np.stack([frames[s].labels for s in steps]),
                visible=np.stack([frames[s].visible for s in steps]),
                cell_size=float(config["grid"]["cell_size"]),
                period=filter_period(config),
            )
        )
    return episodes


def check_replay(
    episode: Episode,
    stored_x: np.ndarray,
    stored_labels: np.ndarray,
    params: DSTParams,
    atol: float = 1.0 / 255.0,
) -> None:
    """Raise if the replay does not reproduce the stored frames.

    Args:
        episode: a recorded episode.
        stored_x: ``(K, 10, H, W)`` BetP t / t-1 read from the shards at ``episode.steps``.
        stored_labels: ``(K, H, W)`` stored labels.
        params: the generation parameters.
        atol: tolerance (uint8-quantised shards are within 1/510 of the truth).

    Raises:
        RuntimeError: naming the episode and the largest difference.
    """
    if not np.array_equal(episode.labels, np.asarray(stored_labels, dtype=episode.labels.dtype)):
        raise RuntimeError(
            f"replay of episode seed {episode.seed} gives other labels than the shard: "
            "the pipeline is not reproducible with the stored config"
        )
    diff = (
        float(np.abs(filter_episode(episode, params) - stored_x).max())
        if len(episode.steps)
        else 0.0
    )
    if diff > atol:
        raise RuntimeError(
            f"replay of episode seed {episode.seed} differs from the stored BetP by {diff:.4f} "
            f"(> {atol:.4f}) with the generation DST parameters"
        )


#: keys of a producer's ``dst`` section that schedule the filter, not DSTParams fields
SCHEDULE_KEYS: tuple[str, ...] = ("update_every",)


def filter_period(config: Mapping[str, Any]) -> int:
    """Steps between two DST updates of a shard's producer.

    ``protocol.update_every`` of the simulator (the paper's protocol fuses at 1 Hz:
    every 10 steps; ``dst.update_every`` is read too), or the top-level
    ``update_every`` of a KITTI conversion (:func:`dstenv.kitti.sequence.default_config`);
    1 when none is set.
    """
    for section in ("protocol", "dst"):
        sec = config.get(section, {}) or {}
        if "update_every" in sec:
            return int(sec["update_every"])
    return int(config.get("update_every", 1))


def generation_params(config: Mapping[str, Any]) -> DSTParams:
    """The :class:`DSTParams` a producer's configuration used (its ``dst`` section
    without the scheduling keys :data:`SCHEDULE_KEYS`)."""
    dst = {k: v for k, v in (config.get("dst", {}) or {}).items() if k not in SCHEDULE_KEYS}
    return DSTParams.from_dict(dst)
