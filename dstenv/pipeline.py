"""The simulation pipeline: world -> LIDAR sweep -> grids -> DST filter -> :class:`Frame`.

One :class:`Pipeline` step is one LIDAR period (0.1 s):

1. the world source advances (ego action or autopilot);
2. the LIDAR sweeps from the ego pose (occluded by buildings and agents);
3. the sweep is ray-cast into the sensor grid, the map is cut into the GIS grid;
4. the :class:`~dstenv.dst.PerceptionGridFilter` fuses both, with the ego motion
   :func:`~dstenv.grid.relative_pose` of the previous and current poses;
5. ground-truth labels and the ``visible`` mask complete the :class:`~dstenv.frame.Frame`.

The world source is pluggable (:data:`WORLD_SOURCES`): ``"city"`` is dstenv's own
:class:`dstenv.sim.World`, ``"highway"`` a highway-env scene
(:class:`dstenv.sim.highway.HighwayWorld`). Any object with the same interface
(``reset(seed)``, ``step(ego_action)``, ``map``, ``agents``, ``ego_pose``,
``ego_speed``, ``time``, ``collision``, ``off_road``) can be passed as ``world=``.

No gymnasium here: the Gymnasium shell is :mod:`dstenv.envs`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any, Protocol

import numpy as np

from dstenv.config import Section, Validated, build_config, one_of
from dstenv.dst import DSTParams, PerceptionGridFilter
from dstenv.frame import Frame
from dstenv.grid import GridSpec, relative_pose
from dstenv.sensing.config import gis_is_exact
from dstenv.sensing.gis import MapError, gis_grid
from dstenv.sensing.labels import label_grid, visible_mask
from dstenv.sim.types import Agents, WorldMap

__all__ = ["WORLD_SOURCES", "WorldSource", "default_config", "Pipeline", "SOURCE_SECTION",
           "FRAME_SECTION"]


class WorldSource(Protocol):
    """What the pipeline needs from a world (dstenv's ``World`` or an adapter)."""

    map: WorldMap
    agents: Agents
    ego_pose: np.ndarray  # (3,) float64 (x [m], y [m], yaw [rad])
    ego_speed: float  # [m/s]
    time: float  # [s]
    collision: bool
    off_road: bool

    def reset(self, seed: int) -> Any: ...

    def step(self, ego_action: Any = None) -> Any: ...


def _city_world(config: Mapping[str, Any], seed: int) -> WorldSource:
    from dstenv.sim.world import World

    return World(config["world"], seed)


def _highway_world(config: Mapping[str, Any], seed: int) -> WorldSource:
    from dstenv.sim.highway import HighwayWorld

    return HighwayWorld(config["highway"], seed)


#: ``config["source"]`` -> factory ``(config, seed) -> world``. Add entries to plug in
#: another simulator.
WORLD_SOURCES: dict[str, Callable[[Mapping[str, Any], int], WorldSource]] = {
    "city": _city_world,
    "highway": _highway_world,
}


def default_config() -> dict[str, Any]:
    """The pipeline's configuration: every subsystem's defaults, one section each.

    Sections: ``source`` (a :data:`WORLD_SOURCES` key), ``world`` (dstenv city
    simulator), ``highway`` (highway-env backend), ``lidar``, ``grid``, ``gis``,
    ``labels``, ``dst`` (:class:`~dstenv.dst.DSTParams` fields) and ``frame``
    (optional outputs).
    """
    from dstenv.sensing.config import default_config as sensing_defaults
    from dstenv.sim.config import default_config as world_defaults
    from dstenv.sim.highway import default_config as highway_defaults

    from dstenv.grid import SECTION as grid_section

    sensing = sensing_defaults()
    return {
        "source": "city",  # "city" (dstenv.sim.World) or "highway" (highway-env scene)
        "world": world_defaults(),
        "highway": highway_defaults(),
        "lidar": sensing["lidar"],
        "grid": grid_section.defaults(),  # height, width [cells], cell_size [m]
        "gis": sensing["gis"],
        "labels": sensing["labels"],
        "dst": DSTParams.default().to_dict(),  # see dstenv.dst.DSTParams
        "frame": _frame_defaults(),
    }


def _frame_defaults() -> dict[str, Any]:
    return {
        "masses": False,  # attach the (32, H, W) masses to every Frame
        # attach extras["lidar_points"]: (B, 2) float32 ego frame [m], NaN = no return
        "lidar_points": False,
    }


def _SOURCE_RULE() -> Any:  # noqa: N802 - read at validation time: WORLD_SOURCES may grow
    return one_of(*WORLD_SOURCES, what="world source")


#: The top-level ``source`` key (a :data:`WORLD_SOURCES` name).
SOURCE_SECTION = Section(lambda: {"source": "city"}, {}, (
    ("source", lambda c: _SOURCE_RULE().check(c["source"], "source") is None,
     "must be a WORLD_SOURCES key"),))
#: The ``frame`` section: optional outputs of every :class:`Frame`.
FRAME_SECTION = Section(_frame_defaults, {})


class Pipeline:
    """A world, a LIDAR and a perception-grid filter, stepped together.

    Args:
        config: overrides of :func:`default_config` (validated: an unknown key raises
            :class:`~dstenv.config.ConfigError` naming it).
        world: an existing world source to drive instead of building one from
            ``config["source"]`` (e.g. a :class:`~dstenv.sim.highway.HighwayWorld`
            around a user's highway-env env).

    Example:
        >>> p = Pipeline({"grid": {"height": 128, "width": 128}})
        >>> frame = p.reset(seed=0)
        >>> frame = p.step()            # autopilot
        >>> frame.fcn_input().shape
        (10, 128, 128)
    """

    def __init__(self, config: Mapping[str, Any] | None = None, world: WorldSource | None = None
                 ) -> None:
        from dstenv.sensing.lidar import Lidar

        self.config = config if isinstance(config, Validated) else build_config(None, config)
        cfg = self.config
        self.spec = GridSpec(**cfg["grid"])
        params = DSTParams.from_dict(cfg["dst"])
        self.lidar = Lidar(cfg["lidar"])
        self.filter = PerceptionGridFilter(self.spec.shape, params, self.spec.cell_size)
        self._world = world
        self.seed = 0
        self.step_index = 0
        self._rng = np.random.default_rng(0)
        self._map_error: MapError | None = None
        self._prev_betp: np.ndarray | None = None
        self._prev_pose: np.ndarray | None = None
        self.sweep: Any = None

    @property
    def world(self) -> WorldSource:
        """The world source (built at the first :meth:`reset`)."""
        if self._world is None:
            raise RuntimeError("Pipeline.world: call reset(seed) first")
        return self._world

    def reset(self, seed: int = 0) -> Frame:
        """Start an episode from ``seed`` and return its first frame.

        The filter starts from total ignorance, so the first frame holds one sweep;
        its ``pignistic_prev`` equals ``pignistic``.
        """
        self.seed = int(seed)
        if self._world is None:
            self._world = WORLD_SOURCES[self.config["source"]](self.config, self.seed)
        else:
            self._world.reset(self.seed)
        self._rng = np.random.default_rng([self.seed, 0x5E45])
        gis = self.config["gis"]
        # one map / localisation error per episode: a persistently wrong map
        self._map_error = (None if gis_is_exact(gis)
                           else MapError.sample(self._world.map, gis, self._rng))
        self.filter.reset()
        self.step_index = 0
        self._prev_pose = None
        self._prev_betp = None
        return self._observe()

    def step(self, action: Any = None) -> Frame:
        """Advance the world by one step with the ego ``action`` and observe.

        Args:
            action: passed to the world's ``step``: ``None`` for the autopilot, or
                what the world source accepts (``(accel [m/s^2], steer [rad])``,
                or a meta-action name for highway-env scenes).
        """
        if self._prev_pose is None:
            raise RuntimeError("Pipeline.step: call reset(seed) first")
        self.world.step(action)
        self.step_index += 1
        return self._observe()

    def _advance(self, action: Any = None) -> None:
        """:meth:`step` without building a :class:`Frame` (no labels, no masses copy).

        The world, LIDAR randomness and filter advance exactly as in :meth:`step`, so
        the frames of later steps are identical; data generation calls this for the
        steps between kept frames.
        """
        if self._prev_pose is None:
            raise RuntimeError("Pipeline.step: call reset(seed) first")
        self.world.step(action)
        self.step_index += 1
        pose, _, _, _, _ = self._sense(False)
        self._prev_pose = pose
        self._prev_betp = self.filter.pignistic()

    def _sense(self, want_masses: bool) -> tuple[np.ndarray, Agents, np.ndarray, np.ndarray,
                                                 np.ndarray]:
        """Sweep, grids and filter update: ``(pose, agents, sensor, gis, masses)``."""
        w, spec = self.world, self.spec
        pose = np.array(w.ego_pose, dtype=np.float64)
        agents = w.agents
        self.sweep = self.lidar.sweep(w.map, agents, pose, self._rng)
        sensor = self.sweep.sensor_grid(spec)
        gis = gis_grid(w.map, pose, spec, self._map_error)
        motion = None if self._prev_pose is None else relative_pose(self._prev_pose, pose)
        masses = self.filter.update(sensor, gis, motion, copy=want_masses)
        return pose, agents, sensor, gis, masses

    def _observe(self) -> Frame:
        w, cfg, spec = self.world, self.config, self.spec
        want_masses = cfg["frame"]["masses"]
        pose, agents, sensor, gis, masses = self._sense(want_masses)
        betp = self.filter.pignistic()
        labels = label_grid(w.map, agents, pose, spec, cfg["labels"]["moving_threshold"])
        extras: dict[str, np.ndarray] = {}
        if cfg["frame"]["lidar_points"]:
            # fixed (B, 2) shape, NaN rows for beams without return: stacks across envs
            extras["lidar_points"] = self.sweep.points.astype(np.float32)
        frame = Frame(
            pignistic=betp,
            pignistic_prev=betp if self._prev_betp is None else self._prev_betp,
            labels=labels,
            visible=visible_mask(sensor),
            sensor=sensor,
            gis=gis,
            ego_pose=pose,
            time=float(w.time),
            seed=self.seed,
            step=self.step_index,
            masses=masses if want_masses else None,
            extras=extras,
        )
        self._prev_pose = pose
        self._prev_betp = betp
        return frame
