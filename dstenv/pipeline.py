"""The simulation pipeline: world -> LIDAR sweep -> grids -> DST filter -> :class:`Frame`.

One :class:`Pipeline` step is one LIDAR period (0.1 s):

1. the world source advances (ego action or autopilot);
2. the LIDAR sweeps from the ego pose (occluded by buildings and agents): the fast
   2-D scanner (``lidar.model = "2d"``) or the 3-D HDL-64E-like one (``"hdl64"``,
   :mod:`dstenv.sensing.lidar3d`), whose point cloud takes KITTI's road to the grid
   (:mod:`dstenv.sensing.cloud`: ground removal, one ray per point);
3. the sweep is ray-cast into the sensor grid, the map is cut into the GIS grid;
4. on fused steps (every ``protocol.update_every``-th) the
   :class:`~dstenv.dst.tracker.GridTracker` fuses both, with the ego motion since
   the previous fused step; other steps carry the last fused BetP;
5. ground-truth labels and the ``visible`` mask complete the :class:`~dstenv.frame.Frame`.

The ``protocol`` section holds the paper's evaluation protocol as options: the fusion
rate (``update_every``: 10 fuses at 1 Hz, t-1 is the previous fused frame), labels
only in a front camera's view (``camera_fov``, the rest
:data:`~dstenv.frame.IGNORE_INDEX`), KITTI's moving rule (``moving_rule =
"displacement"``: 10 cm between fused frames) and KITTI's labels at the rim of road
users (``object_edges = "ignore"``: occupied cells just outside a box are ignored).

The world source is pluggable (:data:`WORLD_SOURCES`): ``"city"`` is dstenv's own
:class:`dstenv.sim.World`, ``"highway"`` a highway-env scene (:class:`dstenv.sim.highway.
HighwayWorld`); any object with their interface (``reset(seed)``, ``step(ego_action)``,
``map``, ``agents``, ``ego_pose``, ``ego_speed``, ``time``, ``collision``, ``off_road``).

No gymnasium here: the Gymnasium shell is :mod:`dstenv.envs`.
"""

from __future__ import annotations

import inspect
import numbers
from collections.abc import Callable, Mapping
from typing import Any, Protocol

import numpy as np

from dstenv.config import ConfigError, Section, Validated, between, build_config, one_of
from dstenv.dst import DSTParams
from dstenv.dst.tracker import GridTracker
from dstenv.frame import IGNORE_INDEX, Frame
from dstenv.grid import GridSpec, camera_mask
from dstenv.sensing.config import gis_is_exact
from dstenv.sensing.gis import MapError, gis_grid
from dstenv.sensing.labels import ignore_object_edges, label_grid, visible_mask
from dstenv.sensing.odometry import Odometry
from dstenv.sim.types import Agents, WorldMap

__all__ = ["WORLD_SOURCES", "MOVING_RULES", "OBJECT_EDGES", "WorldSource", "default_config",
           "camera_mask", "Pipeline", "SOURCE_SECTION", "FRAME_SECTION", "PROTOCOL_SECTION"]

#: ``protocol.moving_rule`` values: the agent's speed against ``labels.moving_threshold``,
#: or KITTI's 10 cm displacement between fused frames.
MOVING_RULES: tuple[str, ...] = ("speed", "displacement")
#: ``protocol.object_edges`` values (:func:`~dstenv.sensing.labels.ignore_object_edges`).
OBJECT_EDGES: tuple[str, ...] = ("map", "ignore")
#: KITTI's moving rule: displacement between two fused frames [m].
KITTI_DISPLACEMENT: float = 0.10


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
    (optional outputs: ``labels`` false leaves ``Frame.labels``/``visible`` None).
    """
    from dstenv.grid import SECTION as grid_section
    from dstenv.sensing.config import default_config as sensing_defaults
    from dstenv.sim.config import default_config as world_defaults
    from dstenv.sim.highway import default_config as highway_defaults

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
        "protocol": _protocol_defaults(),
        "frame": _frame_defaults(),
    }


def _protocol_defaults() -> dict[str, Any]:
    return {  # the paper's evaluation protocol (defaults: fuse every step, all cells)
        # fuse every k-th step (paper: 10 -> 1 Hz, 20 -> 0.5 Hz); t-1 = the previous
        # fused frame; steps in between carry the last fused BetP [steps]
        "update_every": 1,
        # [deg] > 0: label only the cells inside a front camera's horizontal field of
        # view (KITTI's left colour camera: 81), the rest ignored (255); 0: all cells
        "camera_fov": 0.0,
        "moving_rule": "speed",  # "speed" (labels.moving_threshold) or "displacement"
        # occupied cells just outside a road user's box (hits in cells whose centre it
        # misses): "map" labels them by the ground under them, "ignore" as KITTI's
        # converter without a map does (dstenv.sensing.labels.ignore_object_edges)
        "object_edges": "map",
        # the ego motion the filter is given (dstenv.sensing.odometry: a real INS's step
        # errors; 0: exact): along-track std [m], across-track drift std [m], yaw std
        # [deg] per fused step; labels and grids keep the true pose
        "odometry_along": 0.0,
        "odometry_drift": 0.0,
        "odometry_yaw": 0.0,
    }


def _frame_defaults() -> dict[str, Any]:
    return {
        "labels": True,  # compute labels + visible (label_grid, ~15 % of a 256x256 step)
        "masses": False,  # attach the (32, H, W) masses to every Frame
        # attach extras["lidar_points"]: fixed-shape float32, NaN = no return: (B, 2) ego
        # frame [m] for the 2-D LIDAR, (beams, 4) Velodyne rows for hdl64
        "lidar_points": False,
    }


def _source_rule() -> Any:  # read at validation time: WORLD_SOURCES may grow
    return one_of(*WORLD_SOURCES, what="world source")


#: The top-level ``source`` key (a :data:`WORLD_SOURCES` name).
SOURCE_SECTION = Section(lambda: {"source": "city"}, {}, (
    ("source", lambda c: _source_rule().check(c["source"], "source") is None,
     "must be a WORLD_SOURCES key"),))
#: The ``protocol`` section: fusion rate, camera field of view, moving rule.
PROTOCOL_SECTION = Section(_protocol_defaults, {
    "update_every": between(1, 1000, "steps"),
    "camera_fov": between(0.0, 180.0, "deg", hi_open=True),
    "moving_rule": one_of(*MOVING_RULES),
    "object_edges": one_of(*OBJECT_EDGES),
    "odometry_along": between(0.0, 1.0, "m"),
    "odometry_drift": between(0.0, 1.0, "m"),
    "odometry_yaw": between(0.0, 5.0, "deg"),
})
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
        fuse: run the DST filter (default). ``False`` produces the filter's inputs
            only (sensor and GIS grids, pose, labels; ``Frame.pignistic`` and
            ``pignistic_prev`` are None) for a batched filter elsewhere
            (:mod:`dstenv.data.gpu_stream`).

    Example:
        >>> p = Pipeline({"grid": {"height": 128, "width": 128}})
        >>> frame = p.reset(seed=0)
        >>> frame = p.step()            # autopilot
        >>> frame.fcn_input().shape
        (10, 128, 128)
    """

    def __init__(self, config: Mapping[str, Any] | None = None, world: WorldSource | None = None,
                 *, fuse: bool = True) -> None:
        from dstenv.sensing.lidar import Lidar

        self.config = config if isinstance(config, Validated) else build_config(None, config)
        cfg = self.config
        self.spec = GridSpec(**cfg["grid"])
        params = DSTParams.from_dict(cfg["dst"])
        prot = cfg["protocol"]
        self._3d = cfg["lidar"]["model"] == "hdl64"
        from dstenv.sensing.lidar3d import Hdl64

        self.lidar: Any = Hdl64(cfg["lidar"]) if self._3d else Lidar(cfg["lidar"])
        mx, my = cfg["lidar"]["mount_x"], cfg["lidar"]["mount_y"]  # the sensor grid's origin
        if not self.spec.inside(*self.spec.to_cell(np.array([mx]), np.array([my])))[0]:
            raise ConfigError(f"lidar.mount_x / mount_y {mx:g}, {my:g} m: outside the grid "
                              f"(its extent {self.spec.extent}); mount the LIDAR on it")
        self.fuse = bool(fuse)
        self.tracker = GridTracker(self.spec.shape, params, self.spec.cell_size)
        self.odometry = Odometry(self.config["protocol"])
        # the pose the filter got at the last fused step (true unless protocol.odometry_*)
        self.filter_pose: np.ndarray | None = None
        self.camera = (camera_mask(self.spec, prot["camera_fov"]) if prot["camera_fov"] > 0
                       else None)
        if world is None and cfg["source"] == "city" and cfg["world"]["map"]["kind"] == "osm":
            from dstenv.sim.osm import check_osm_file  # now, not at the first reset

            check_osm_file(cfg["world"]["map"])
        self._world = world
        self.seed = 0
        self.step_index = 0
        self._rng = np.random.default_rng(0)
        self._map_error: MapError | None = None
        self._last: tuple[np.ndarray, float] | None = None  # pose and time of the last step
        self.sweep: Any = None

    @property
    def filter(self) -> Any:
        """The :class:`~dstenv.dst.PerceptionGridFilter` inside :attr:`tracker`."""
        return self.tracker.filter

    @property
    def world(self) -> WorldSource:
        """The world source (built at the first :meth:`reset`)."""
        if self._world is None:
            raise RuntimeError("Pipeline.world: call reset(seed) first")
        return self._world

    def reset(self, seed: int = 0, keep_map: bool = False) -> Frame:
        """Start an episode from ``seed`` and return its first frame.

        The filter starts from total ignorance, so the first frame holds one sweep;
        its ``pignistic_prev`` equals ``pignistic``. ``seed``: an integer >= 0.
        ``keep_map``: drive the current map again, all else from ``seed`` (city world).
        """
        if not isinstance(seed, numbers.Integral) or isinstance(seed, bool) or not (
                0 <= seed < 2**63):  # (a larger one failed in the shard writer, at its end)
            raise ValueError(f"Pipeline.reset: seed must be an integer >= 0, got {seed!r} "
                             "(at most 2**63 - 1)")
        if not isinstance(keep_map, bool):  # ("no" was true)
            raise ValueError(f"Pipeline.reset: keep_map must be True or False, got {keep_map!r}")
        if keep_map and self._world is None:
            raise RuntimeError("Pipeline.reset(keep_map=True): reset once without it first")
        if keep_map and "keep_map" not in inspect.signature(self._world.reset).parameters:
            raise ValueError(f"Pipeline.reset(keep_map=True): a {type(self._world).__name__} "
                             "cannot keep its map (the city World can)")
        self.seed = int(seed)
        if self._world is None:
            self._world = WORLD_SOURCES[self.config["source"]](self.config, self.seed)
        else:
            self._world.reset(self.seed, **({"keep_map": True} if keep_map else {}))
        self._rng = np.random.default_rng([self.seed, 0x5E45])
        gis = self.config["gis"]
        # one map / localisation error per episode: a persistently wrong map
        self._map_error = (None if gis_is_exact(gis)
                           else MapError.sample(self._world.map, gis, self._rng))
        self.tracker.reset()
        self.odometry.reset(self.seed)
        self.step_index = 0
        self._last = None
        return self._observe()

    def step(self, action: Any = None) -> Frame:
        """Advance the world by one step with the ego ``action`` and observe.

        Args:
            action: passed to the world's ``step``: ``None`` for the autopilot, or
                what the world source accepts (``(accel [m/s^2], steer [rad])``,
                or a meta-action name for highway-env scenes).
        """
        if self._last is None:
            raise RuntimeError("Pipeline.step: call reset(seed) first")
        self.world.step(action)
        self.step_index += 1
        return self._observe()

    def advance(self, action: Any = None) -> None:
        """:meth:`step` without building a :class:`Frame` (no labels, no masses copy).

        The world and filter advance exactly as in :meth:`step`, so the frames of later
        steps are identical; data generation calls this for the steps between kept
        frames, an RL frame-skip for the skipped steps. Steps that are not fused
        (``protocol.update_every``) only step the world: no sweep, no grids.
        """
        if self._last is None:
            raise RuntimeError("Pipeline.advance: call reset(seed) first")
        self.world.step(action)
        self.step_index += 1
        if self.fuse and not self.fused_step:
            # (the LIDAR stream is keyed by the step: the next sweep is the one step() gives)
            w = self.world
            self._last = (np.array(w.ego_pose, dtype=np.float64), float(w.time))
            return
        self._sense(False, frame=False)

    @property
    def fused_step(self) -> bool:
        """Whether the current step feeds the DST filter: every ``protocol.update_every``-th
        step from step 0, when the pipeline fuses at all (then :attr:`filter_pose` is
        the pose it was given)."""
        return self.fuse and self.step_index % self.config["protocol"]["update_every"] == 0

    def _sweep_rng(self) -> np.random.Generator:
        """This step's LIDAR noise, keyed by (seed, step): the same whatever was swept before."""
        return np.random.default_rng([self.seed, 0x5E45, 0x5EE9, self.step_index])

    def _sense(self, want_masses: bool, frame: bool = True
               ) -> tuple[np.ndarray, Agents, np.ndarray, np.ndarray, np.ndarray]:
        """Sweep, grids and (on fused steps) the tracker: ``(pose, agents, sensor, gis,
        masses)``; ``masses`` is the last fused grid. Without a ``frame`` to build, a
        fused step skips BetP when every step is fused (the next frame is then built on
        a fused step, whose tracker step computes its t-1 from the masses left here:
        ``GridTracker.step(betp=False)``)."""
        w, spec = self.world, self.spec
        pose = np.array(w.ego_pose, dtype=np.float64)
        agents = w.agents
        if not self._3d:
            self.sweep = self.lidar.sweep(w.map, agents, pose, self._sweep_rng())
        else:  # the 3-D LIDAR skews with the ego's motion within the turn
            yaw_rate = 0.0
            if self._last is not None and float(w.time) > self._last[1]:
                dyaw = (pose[2] - self._last[0][2] + np.pi) % (2 * np.pi) - np.pi
                yaw_rate = float(dyaw) / (float(w.time) - self._last[1])
            self.sweep = self.lidar.sweep(w.map, agents, pose, self._sweep_rng(),
                                          float(w.ego_speed), yaw_rate)
        self._last = (pose, float(w.time))
        sensor = self.sweep.sensor_grid(spec)
        gis = gis_grid(w.map, pose, spec, self._map_error)
        if not self.fuse:
            return pose, agents, sensor, gis, None
        every = self.config["protocol"]["update_every"]
        if self.fused_step:
            self.filter_pose = self.odometry.estimate(pose)
            self.tracker.step(sensor, gis, self.filter_pose, betp=frame or every > 1)
        masses = self.tracker.filter.masses
        return pose, agents, sensor, gis, masses.copy() if want_masses else masses

    def _observe(self) -> Frame:
        w, cfg, spec = self.world, self.config, self.spec
        want_masses = cfg["frame"]["masses"]
        pose, agents, sensor, gis, masses = self._sense(want_masses)
        # labels are ground truth for datasets; an RL env that does not show them skips them
        labels = None
        if cfg["frame"]["labels"]:
            labels = label_grid(w.map, agents, pose, spec, self.moving_threshold)
            if cfg["protocol"]["object_edges"] == "ignore":
                ignore_object_edges(labels, sensor, IGNORE_INDEX)
            if self.camera is not None:
                labels[~self.camera] = IGNORE_INDEX
        extras: dict[str, np.ndarray] = {}
        if cfg["frame"]["lidar_points"]:  # fixed shape, NaN rows: stacks across envs
            extras["lidar_points"] = (self.sweep.points.astype(np.float32)
                                      if not self._3d else self.sweep.dense())
        # the last fused BetP and its t-1 (step 0 is always fused)
        betp, betp_prev = self.tracker.latest() if self.fuse else (None, None)
        return Frame(
            pignistic=betp,
            pignistic_prev=betp_prev,
            labels=labels,
            visible=visible_mask(sensor) if labels is not None else None,
            sensor=sensor,
            gis=gis,
            ego_pose=pose,
            time=float(w.time),
            seed=self.seed,
            step=self.step_index,
            masses=masses if want_masses else None,
            extras=extras,
        )

    @property
    def moving_threshold(self) -> float:
        """Speed above which an agent is labelled moving [m/s] (see ``protocol.moving_rule``)."""
        cfg = self.config
        if cfg["protocol"]["moving_rule"] == "speed":
            return float(cfg["labels"]["moving_threshold"])
        dt = float(cfg["world"]["dt"]) if cfg["source"] == "city" else 0.1
        return KITTI_DISPLACEMENT / (dt * cfg["protocol"]["update_every"])
