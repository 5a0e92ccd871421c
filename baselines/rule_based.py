"""Rule-based reference drivers for the DSTGrid envs, in one readable file.

* ``grid`` (default): :class:`GridRuleDriver`, a hand-written driver that sees only
  the observation PPO sees (grid, ego vector, route; the grid's geometry from the
  env config): it slows for bends and junctions, stops for a red light and for
  obstacles the grid shows on its route. Not privileged: what it cannot see (cars
  hidden behind a corner building) surprises it as much as a learner.
* ``grid-tuned``: the same driver with :data:`TUNED_PARAMS`, its parameters searched
  on validation seeds by ``tune_rule.py``: the strongest non-learned perception
  driver, the one a learned driver has to beat.
* ``autopilot``: the world's own autopilot drives (the env's ``action.type =
  "autopilot"``): route following, IDM car following, right of way at junctions
  and crosswalks, all from the simulator's ground truth, so hidden cross traffic is
  no surprise to it: a *privileged* upper reference, not a perception baseline.
* ``constant``: one fixed action every step (default ``2`` = FASTER), a grid-blind
  driver: what ignoring the perception grid costs.
* ``advice``: :class:`AdvicePolicy`, the action closest to what the autopilot would do
  now (``info["autopilot_action"]``: the world's autopilot asked about the state the
  meta-actions drive, with the env's ``info.autopilot``); privileged. The traffic does
  not queue an ego it does not drive, so this collides where the autopilot does not.
* ``cautious``: :class:`CautiousDriver`, the slower of ``grid-tuned``'s action and
  ``advice``'s: privileged, a teacher for imitation, not a baseline to beat.

Run::

    python baselines/rule_based.py --driver grid --episodes 20
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np

from rl_common import EnvArgs, EpisodeResult, evaluate_policy, make_env, opt, parse_args
from rl_common import cli, output_file, report_run

DRIVERS = ("grid", "grid-tuned", "autopilot", "constant", "advice", "cautious")
#: :class:`GridRuleDriver` parameters chosen on validation seeds in PPO's config (collision
#: -30, off-road -10, ``action.repeat = 3``, 200 decisions) by ``tune_rule.py`` in two
#: stages: 16 settings on seeds 20000-20049 (``benchmarks/search/rule-driver.json``), then
#: the defaults and the five best on seeds 20050-20249; this is the ``best`` row of
#: ``benchmarks/search/rule-driver-stage2.json`` (a test checks that they agree). The
#: others keep their defaults. (Earlier searches: ``rule-driver-v2*.json`` without
#: ``corridor_static``, ``rule-driver-v1*.json`` before the give-way rule.)
TUNED_PARAMS: dict[str, float] = {"corridor_static": 0.9, "give_way_line": 2.0,
                                   "give_way_moving": 0.5, "margin": 6.0}
#: ``--env-config`` the autopilot driver adds: the world's own driver.
AUTOPILOT_CONFIG: dict[str, Any] = {"action": {"type": "autopilot"}}
#: ``--env-config`` the cautious driver adds: the autopilot's advice in ``info``.
ADVICE_CONFIG: dict[str, Any] = {"info": {"autopilot": True}}


@dataclass
class Args(EnvArgs):
    """Run a rule-based driver on a DSTGrid env."""

    driver: str = opt("grid", "grid | grid-tuned | autopilot | constant | advice | cautious")
    constant_action: int = opt(2, "the action of the constant driver (2 = FASTER)")
    episodes: int = opt(10, "episodes, one per seed")
    seed: int = opt(10_000, "first seed (episode k uses seed + k)")
    csv: str = opt("", "write per-episode results to this CSV file")


class GridRuleDriver:
    """Speed rules on the ``"dict"`` observation of the speed / discrete meta-actions.

    Each step it picks a wanted speed among the env's ``target_speeds`` and steps the
    target speed towards it (SLOWER / IDLE / FASTER):

    * obstacle: the first grid cell within ``corridor`` m of the route ahead whose
      BetP(static) + BetP(moving) exceeds ``occupied`` sets the distance to stop in;
      the wanted speed is the fastest whose braking distance at ``brake`` m/s^2 plus
      ``margin`` m fits before it, and the slowest once the current speed's does not;
      a cell with more BetP(static) than BetP(moving) counts only within
      ``corridor_static`` m (default: ``corridor``): with 1 m cells, the side of a car
      parked 0.5 m clear of the ego's path lights the cells 1 m beside the route, and
      at 1.4 m the driver waited behind such cars to the end of the episode;
    * bend: the route turns by more than ``bend_angle`` rad within ``bend_range`` m:
      at most the middle speed;
    * junction within ``junction_range`` m: at most the middle speed unless its
      signal shows green; a red light closer than the braking distance: stop;
    * give way (``give_way``): at a yield or stop junction, once the line is within
      ``give_way_line`` m plus the braking distance, it moves on only while slower
      than ``give_way_speed`` m/s and the junction area shows no moving cell
      (BetP(moving) above ``give_way_moving`` from 3 m before the line to
      ``give_way_ahead`` m past it, within ``give_way_side`` m either side of the
      ego's axis), else it stops: it creeps up to the line, looking into the side
      streets that the corner buildings hid, as a driver does. Without it the driver
      entered such junctions at the middle speed and met the cross traffic that has
      the right of way there (most of its collisions).

    Args:
        corridor, occupied, margin, brake, bend_angle, bend_range, junction_range,
        give_way_line, give_way_speed, give_way_moving, give_way_ahead,
        give_way_side, corridor_static: as above (``corridor_static`` ``None``: the
        same as ``corridor``).
        give_way: apply the give-way rule (False: the driver before it).
    """

    name = "rule-based (grid)"

    def __init__(self, corridor: float = 1.4, occupied: float = 0.5, margin: float = 4.0,
                 brake: float = 2.4, bend_angle: float = 0.35, bend_range: float = 25.0,
                 junction_range: float = 20.0, give_way_line: float = 2.0,
                 give_way_speed: float = 0.6, give_way_moving: float = 0.35,
                 give_way_ahead: float = 14.0, give_way_side: float = 20.0,
                 give_way: bool = True, corridor_static: float | None = None) -> None:
        self.corridor, self.occupied, self.margin, self.brake = corridor, occupied, margin, brake
        self.corridor_static = corridor if corridor_static is None else corridor_static
        self.bend_angle, self.bend_range = bend_angle, bend_range
        self.junction_range = junction_range
        self.give_way = bool(give_way)
        self.give_way_line, self.give_way_speed = give_way_line, give_way_speed
        self.give_way_moving = give_way_moving
        self.give_way_ahead, self.give_way_side = give_way_ahead, give_way_side

    @staticmethod
    def check(env: gym.Env) -> None:
        """Refuse an env this driver cannot drive (before any episode)."""
        cfg = env.unwrapped.config
        obs_cfg = cfg["observation"]
        if obs_cfg["type"] != "dict" or obs_cfg["grid"] != "image":
            raise ValueError("GridRuleDriver: needs observation.type 'dict' with grid 'image'")
        kind = cfg["action"]["type"]  # a continuous action space has no meanings
        if kind == "continuous" or \
                env.unwrapped.get_action_meanings()[:3] != ["SLOWER", "IDLE", "FASTER"]:
            raise ValueError(f"GridRuleDriver: needs the speed or discrete meta-actions, not "
                             f"action.type {kind!r}")

    def reset(self, env: gym.Env, seed: int) -> None:
        from dstenv.envs.navigation import EGO_FEATURES, JUNCTION_RANGE, SPEED_SCALE

        self.check(env)
        cfg = env.unwrapped.config
        obs_cfg = cfg["observation"]
        self.speeds = np.asarray(cfg["action"]["target_speeds"], np.float64)
        self.cell = float(cfg["grid"]["cell_size"])
        self.shape = (int(cfg["grid"]["height"]), int(cfg["grid"]["width"]))
        self.route_scale = obs_cfg["route_points"] * obs_cfg["route_spacing"]
        self.ego_index = {name: i for i, name in enumerate(EGO_FEATURES)}
        self.speed_scale, self.junction_scale = SPEED_SCALE, JUNCTION_RANGE
        h, w = self.shape  # ego-frame coordinates of the cells: x forward, y left [m]
        self._cell_x = ((h // 2 - np.arange(h)) * self.cell)[:, None]
        self._cell_y = np.abs((w // 2 - np.arange(w)) * self.cell)[None, :]

    def _route_path(self, route: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Route from the ego, 0.5 m apart: ego-frame points ``(M, 2)`` and their
        distances along the route ``(M,)``."""
        pts = np.vstack([[0.0, 0.0], route.reshape(-1, 2) * self.route_scale])
        seg = np.hypot(*np.diff(pts, axis=0).T)
        s = np.concatenate([[0.0], np.cumsum(seg)])
        d = np.arange(0.0, s[-1], 0.5)
        return np.stack([np.interp(d, s, pts[:, 0]), np.interp(d, s, pts[:, 1])], 1), d

    def _obstacle_distance(self, grid: np.ndarray, path: np.ndarray, dist: np.ndarray) -> float:
        """Route distance [m] to the first path point with an occupied cell more than 2 m
        ahead of the ego (not its own footprint) within ``corridor`` m (inf: none).

        Only the cells of a window around each path point can be that close, so those
        are tested: ``(M, K)`` distances instead of path points x occupied cells."""
        occ = (grid[2].astype(np.float32) + grid[3]) / 255.0 > self.occupied
        h, w = self.shape
        i0, j0 = h // 2, w // 2
        k = int(np.ceil(max(self.corridor, self.corridor_static) / self.cell)) + 1
        di, dj = np.meshgrid(np.arange(-k, k + 1), np.arange(-k, k + 1), indexing="ij")
        rows = np.rint(i0 - path[:, 0] / self.cell).astype(np.int64)[:, None] + di.ravel()
        cols = np.rint(j0 - path[:, 1] / self.cell).astype(np.int64)[:, None] + dj.ravel()
        inside = (rows >= 0) & (rows < h) & (cols >= 0) & (cols < w)
        r, c = np.where(inside, rows, 0), np.where(inside, cols, 0)
        cx, cy = (i0 - r) * self.cell, (j0 - c) * self.cell
        d2 = (path[:, 0:1] - cx) ** 2 + (path[:, 1:2] - cy) ** 2  # (M, K)
        # a static-dominant cell blocks only within ``corridor_static`` of the route
        static = grid[2] > grid[3]
        reach = np.where(static[r, c], self.corridor_static, self.corridor)
        hit = inside & occ[r, c] & (cx > 2.0) & (d2 < reach ** 2)
        near = hit.any(1)
        return float(dist[np.argmax(near)]) if near.any() else float("inf")

    def _junction_clear(self, grid: np.ndarray, line: float) -> bool:
        """No moving cell in the junction area of a line ``line`` m ahead (see the
        class doc: ``(4, H, W) uint8`` image grid)."""
        area = ((self._cell_x > max(line - 3.0, 1.0)) & (self._cell_x < line + self.give_way_ahead)
                & (self._cell_y < self.give_way_side))
        return not (area & (grid[3] > 255.0 * self.give_way_moving)).any()

    def _bend_ahead(self, path: np.ndarray, dist: np.ndarray) -> bool:
        ahead = path[dist <= self.bend_range]
        if len(ahead) < 3:
            return False
        heading = np.arctan2(*np.diff(ahead, axis=0)[:, ::-1].T)
        return bool(np.abs(np.unwrap(heading) - heading[0]).max() > self.bend_angle)

    def act(self, obs: Any, info: dict[str, Any]) -> int:
        ego, k = obs["ego"], self.ego_index
        v = float(ego[k["speed"]]) * self.speed_scale
        target = float(ego[k["target_speed"]]) * self.speed_scale
        path, dist = self._route_path(obs["route"])
        room = self._obstacle_distance(obs["grid"], path, dist) - self.margin
        stop_dist = self.speeds ** 2 / (2 * self.brake)
        braking = v * v / (2 * self.brake)  # the current speed's stopping distance [m]
        fits = self.speeds[stop_dist <= max(room, 0.0)]
        want = float(fits.max()) if len(fits) else float(self.speeds.min())
        if braking >= room:  # the current speed no longer stops in time
            want = float(self.speeds.min())
        middle = float(self.speeds[len(self.speeds) // 2])
        if self._bend_ahead(path, dist):
            want = min(want, middle)
        junction = float(ego[k["junction_dist"]]) * self.junction_scale
        green = ego[k["signal_green"]] > 0.5
        if junction <= self.junction_range and not green:
            want = min(want, middle)
            if ego[k["control_signal"]] > 0.5 and junction <= braking + 3.0:
                want = float(self.speeds.min())  # a red light
            yields = ego[k["control_yield"]] > 0.5 or ego[k["control_stop"]] > 0.5
            if (self.give_way and yields
                    and 0.0 < junction <= self.give_way_line + braking + 0.5
                    and not (v < self.give_way_speed
                             and self._junction_clear(obs["grid"], junction))):
                want = float(self.speeds.min())  # stop; creep on only when slow and clear
        if want < target - 1e-6:
            return 0  # SLOWER
        if want > target + 1e-6:
            return 2  # FASTER
        return 1  # IDLE


class AutopilotPolicy:
    """The world's autopilot; needs an env with ``action.type = "autopilot"``."""

    name = "autopilot (privileged)"

    def reset(self, env: gym.Env, seed: int) -> None:
        if env.unwrapped.get_action_meanings() != ["AUTOPILOT"]:
            raise ValueError("AutopilotPolicy: build the env with AUTOPILOT_CONFIG")

    def act(self, obs: Any, info: dict[str, Any]) -> int:
        return 0


class AdvicePolicy:
    """The action closest to the autopilot's command; needs :data:`ADVICE_CONFIG`."""

    name = "autopilot advice (privileged)"

    def reset(self, env: gym.Env, seed: int) -> None:
        if not env.unwrapped.config["info"]["autopilot"]:
            raise ValueError(f"{type(self).__name__}: build the env with ADVICE_CONFIG "
                             "(info.autopilot = true)")

    def act(self, obs: Any, info: dict[str, Any]) -> int:
        return int(info["autopilot_action"])


class SlowerOf:
    """Each step the slower of two drivers' ``Discrete(3)`` speed actions (SLOWER <
    IDLE < FASTER): whichever sees danger slows the car.

    A learned policy held back by a rule driver this way is *shielded* by it
    (``evaluate.py --shield``; Alshiekh et al., AAAI 2018); :class:`CautiousDriver`
    is ``grid-tuned`` with the autopilot's advice. Both read the same observation and
    ``info``, so the pair is privileged only where one of the two is.
    """

    def __init__(self, first: Any, second: Any, name: str) -> None:
        self.first, self.second, self.name = first, second, name

    def reset(self, env: gym.Env, seed: int) -> None:
        if env.unwrapped.get_action_meanings() != ["SLOWER", "IDLE", "FASTER"]:
            raise ValueError(f"{self.name}: needs the speed actions (SLOWER, IDLE, FASTER)")
        self.first.reset(env, seed)
        self.second.reset(env, seed)

    def act(self, obs: Any, info: dict[str, Any]) -> int:
        return min(int(self.first.act(obs, info)), int(self.second.act(obs, info)))


class CautiousDriver(SlowerOf):
    """The slower of ``grid-tuned``'s action and the autopilot's advice.

    Each step it takes the lower of the two ``Discrete(3)`` speed actions (SLOWER <
    IDLE < FASTER): the tuned grid driver's and ``info["autopilot_action"]``, the action
    closest to what the world's autopilot would do now (privileged: it reads the
    traffic's ground truth and its junction queue). Neither alone avoids collisions:
    the traffic does not give way to an ego it does not queue, so the autopilot's
    advice, followed, collides where its own driving does not; where either sees
    danger, this driver slows. Needs an env with :data:`ADVICE_CONFIG`.
    """

    def __init__(self) -> None:
        super().__init__(grid_driver(True), AdvicePolicy(),
                         "cautious: min(grid-tuned, autopilot advice) (privileged)")


class ConstantPolicy:
    """The same action every step (a grid-blind driver)."""

    def __init__(self, action: int) -> None:
        self.action = int(action)
        self.name = f"constant action {self.action}"

    def reset(self, env: gym.Env, seed: int) -> None:
        if not env.action_space.contains(self.action):
            raise ValueError(f"--constant-action {self.action}: not in {env.action_space}")

    def act(self, obs: Any, info: dict[str, Any]) -> int:
        return self.action


def grid_driver(tuned: bool = False) -> GridRuleDriver:
    """The grid rule driver with its default parameters (``grid``) or
    :data:`TUNED_PARAMS` (``grid-tuned``, named so in tables): the one home of that
    choice for the reference drivers, residual PPO and the DAgger warm start."""
    if not tuned:
        return GridRuleDriver()
    driver = GridRuleDriver(**TUNED_PARAMS)
    driver.name = "rule-based (grid, tuned)"
    return driver


#: DAgger teachers (``ppo_grid.py --warm-start``) -> the ``--env-config`` they need
TEACHERS: dict[str, dict[str, Any]] = {"grid": {}, "grid-tuned": {}, "cautious": ADVICE_CONFIG}


def teacher(name: str) -> tuple[Any, str]:
    """A DAgger teacher of :data:`TEACHERS` and how ``model.json`` describes it."""
    if name == "cautious":
        driver = CautiousDriver()
        return driver, f"dagger from {driver.name}"
    tuned = name == "grid-tuned"
    return grid_driver(tuned), "dagger from the grid rule driver" + (
        f" (tuned: {TUNED_PARAMS})" if tuned else "")


#: rule drivers that can shield a learned policy (``evaluate.py --shield``)
SHIELDS = ("grid", "grid-tuned")


def check_shield(shield: str) -> None:
    """Raise ``ValueError`` unless ``shield`` is one of :data:`SHIELDS`."""
    if shield not in SHIELDS:
        raise ValueError(f"--shield: expected one of {SHIELDS}, got {shield!r}")


def shielded(policy: Any, shield: str) -> SlowerOf:
    """``policy`` held back by the rule driver ``shield`` of :data:`SHIELDS`: each step
    the slower of the two actions, named ``"<policy> + shield <shield>"``."""
    check_shield(shield)
    return SlowerOf(policy, grid_driver(shield == "grid-tuned"),
                    f"{policy.name} + shield {shield}")


def reference_driver(name: str, args: EnvArgs, constant_action: int = 2) -> tuple[Any, gym.Env]:
    """A reference driver by name and the env it drives."""
    if name in ("grid", "grid-tuned", "constant"):  # each checks its env before an episode
        env = make_env(args)
        policy = (ConstantPolicy(constant_action) if name == "constant" else
                  grid_driver(name == "grid-tuned"))
        try:
            policy.reset(env, 0)  # reads the config only: refuses an env it cannot drive
        except ValueError:
            env.close()
            raise
        return policy, env
    if name == "autopilot":
        return AutopilotPolicy(), make_env(args, AUTOPILOT_CONFIG)
    if name in ("advice", "cautious"):
        return (AdvicePolicy() if name == "advice" else CautiousDriver()), make_env(
            args, ADVICE_CONFIG)
    raise ValueError(f"unknown driver {name!r}; known: {', '.join(DRIVERS)}")


def run(args: Args) -> tuple[str, list[EpisodeResult]]:
    """Evaluate the driver of ``args``; returns its name and the episodes."""
    if args.driver not in DRIVERS:
        raise ValueError(f"--driver: expected one of {DRIVERS}, got {args.driver!r}")
    policy, env = reference_driver(args.driver, args, args.constant_action)
    seeds = range(args.seed, args.seed + args.episodes)
    try:
        results = evaluate_policy(env, policy, seeds, log=print)
    finally:
        env.close()
    return policy.name, results


def main(argv: list[str] | None = None) -> dict[str, float]:
    """Command-line entry point; returns the summary (:func:`rl_common.summarize`)."""
    args = parse_args(Args, argv)
    output_file(args.csv, "--csv")  # before the episodes
    name, results = run(args)
    return report_run(name, results, args)


if __name__ == "__main__":
    cli(main)
