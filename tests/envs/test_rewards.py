"""Reward terms: hand-computed values."""

from __future__ import annotations

import pytest

from dstenv.envs.rewards import StepOutcome, default_reward_config, reward_terms


def test_cruising_step():
    cfg = default_reward_config()
    t = reward_terms(StepOutcome(progress=0.9, speed=4.5, decel=0.0, collision=False,
                                 off_road=False), cfg)
    assert t["progress"] == pytest.approx(0.09)  # 0.1 / m * 0.9 m
    assert t["speed"] == pytest.approx(0.025)  # 0.05 * 4.5 / 9
    assert t["collision"] == t["off_road"] == t["hard_brake"] == t["arrived"] == 0.0


def test_crash_with_hard_braking():
    cfg = default_reward_config()
    t = reward_terms(StepOutcome(progress=-0.2, speed=20.0, decel=6.0, collision=True,
                                 off_road=True, arrived=False), cfg)
    assert t["progress"] == pytest.approx(-0.02)
    assert t["speed"] == pytest.approx(0.05)  # capped at the target speed
    assert t["collision"] == -10.0 and t["off_road"] == -5.0 and t["hard_brake"] == -0.5
    assert sum(t.values()) == pytest.approx(-0.02 + 0.05 - 15.5)


def test_braking_at_threshold_is_not_hard():
    cfg = default_reward_config()
    t = reward_terms(StepOutcome(0.0, 0.0, decel=2.5, collision=False, off_road=False), cfg)
    assert t["hard_brake"] == 0.0 and t["speed"] == 0.0


def test_slower_meta_action_brakes_comfortably():
    """A SLOWER meta-action never earns the hard-braking penalty (issue 8's finding)."""
    import gymnasium as gym

    import dstenv  # noqa: F401
    from .conftest import SMALL_CITY

    env = gym.make("DSTGrid-v0", config=SMALL_CITY)
    env.reset(seed=4)
    speeds, brakes = [], []
    for action in [2] * 40 + [0] * 30:  # reach the top speed, then slow down twice
        _, _, terminated, truncated, info = env.step(action)
        speeds.append(env.unwrapped.pipeline.world.ego_speed)
        brakes.append(info["rewards"]["hard_brake"])
        if terminated or truncated:
            break
    env.close()
    assert max(speeds) > 6.0 and speeds[-1] < max(speeds) - 3.0  # it did slow down
    assert all(b == 0.0 for b in brakes)


def test_junction_speed_term_is_off_by_default():
    cfg = default_reward_config()
    t = reward_terms(StepOutcome(0.9, 9.0, 0.0, False, False, junction_dist=5.0), cfg)
    assert t["junction_speed"] == 0.0


def test_junction_speed_term_hand_computed():
    cfg = {**default_reward_config(), "junction_speed": -0.5}
    near = StepOutcome(0.9, 9.0, 0.0, False, False, junction_dist=12.0)
    assert reward_terms(near, cfg)["junction_speed"] == pytest.approx(-0.25)  # -0.5 * 4.5 / 9
    inside = StepOutcome(0.9, 6.3, 0.0, False, False, junction_dist=0.0)
    assert reward_terms(inside, cfg)["junction_speed"] == pytest.approx(-0.1)  # -0.5 * 1.8 / 9
    slow = StepOutcome(0.9, 4.0, 0.0, False, False, junction_dist=12.0)
    far = StepOutcome(0.9, 9.0, 0.0, False, False, junction_dist=20.5)
    green = StepOutcome(0.9, 9.0, 0.0, False, False, junction_dist=3.0, junction_green=True)
    none = StepOutcome(0.9, 9.0, 0.0, False, False)  # no junction on the route
    for out in (slow, far, green, none):
        assert reward_terms(out, cfg)["junction_speed"] == 0.0


def test_junction_speed_term_in_the_env():
    """The env feeds the world's next junction to the term: a fast approach pays it,
    and exactly where the world says the ego is within range of a non-green junction."""
    import gymnasium as gym

    import dstenv  # noqa: F401
    from .conftest import SMALL_CITY

    reward = {"junction_speed": -1.0, "junction_speed_limit": 2.0, "junction_range": 30.0}
    env = gym.make("DSTGrid-v0", config={**SMALL_CITY, "reward": reward})
    env.reset(seed=4)
    world = env.unwrapped.pipeline.world
    paid = 0
    for _ in range(80):
        _, _, terminated, truncated, info = env.step(2)  # FASTER
        dist, _, green = world.next_junction()
        want = 0.0
        if dist <= 30.0 and not green:
            want = -max(world.ego_speed - 2.0, 0.0) / 9.0
        assert info["rewards"]["junction_speed"] == pytest.approx(want, abs=1e-9)
        paid += want < 0
        if terminated or truncated:
            break
    env.close()
    assert paid > 0


def test_give_way_term_hand_computed():
    assert default_reward_config()["give_way"] == 0.0  # off by default
    cfg = {**default_reward_config(), "give_way": -5.0}
    fast = StepOutcome(0.9, 4.5, 0.0, False, False, junction_dist=0.0, entered_give_way=True,
                       slowest_approach=3.0)
    assert reward_terms(fast, cfg)["give_way"] == -5.0
    # slowed to give_way_speed before the line: given way, whatever the speed inside
    slowed = StepOutcome(0.9, 4.5, 0.0, False, False, junction_dist=0.0,
                         entered_give_way=True, slowest_approach=1.5)
    assert reward_terms(slowed, cfg)["give_way"] == 0.0
    inside = StepOutcome(0.9, 4.5, 0.0, False, False, junction_dist=0.0,
                         slowest_approach=3.0)  # not entered on this step
    assert reward_terms(inside, cfg)["give_way"] == 0.0


def test_give_way_term_in_the_env():
    """Paid exactly on the steps that take the ego into a yield or stop junction when it
    did not slow to give_way_speed over the steps that began within give_way_range of the
    entry (the world's next junction tells where); a driver that stops first never pays."""
    import gymnasium as gym

    import dstenv  # noqa: F401
    from dstenv.envs.rewards import GIVE_WAY

    from .conftest import SMALL_CITY

    reward = {"give_way": -5.0, "give_way_speed": 1.5, "give_way_range": 5.0}
    paid = entered_slow = 0
    for seed in range(4, 10):
        for stop_first in (False, True):
            env = gym.make("DSTGrid-v0", config={**SMALL_CITY, "reward": reward})
            env.reset(seed=seed)
            world = env.unwrapped.pipeline.world
            slowest = float("inf")
            for _ in range(250):
                before, control, _ = world.next_junction()
                gw = before > 0.0 and control in GIVE_WAY
                if not gw:
                    slowest = float("inf")
                elif before <= 5.0:
                    slowest = min(slowest, world.ego_speed)
                # FASTER; the careful driver creeps (below ~1 m/s) within 20 m of a
                # give-way line
                action = 0 if stop_first and gw and before <= 20.0 and world.ego_speed > 1.0 \
                    else 2
                _, _, terminated, truncated, info = env.step(action)
                entered = gw and world.next_junction()[0] == 0.0
                want = -5.0 if entered and slowest > 1.5 else 0.0
                assert info["rewards"]["give_way"] == want
                paid += want < 0
                entered_slow += entered and want == 0.0
                if entered:
                    slowest = float("inf")
                if terminated or truncated:
                    break
            env.close()
    assert paid > 0 and entered_slow > 0


def test_give_way_watch_tracks_the_slowest_approach_speed():
    from dstenv.envs.rewards import GiveWayWatch

    cfg = {**default_reward_config(), "give_way_range": 5.0}
    w = GiveWayWatch()
    for dist, speed in ((12.0, 9.0), (6.0, 6.0), (4.5, 4.0), (2.0, 1.2), (0.8, 2.5)):
        w.before(dist, True, speed, cfg)  # 9 and 6 m/s: before the range
        assert w.after(dist - 1.0) == (False, 1.2 if dist <= 2.0 else (4.0 if dist < 5 else
                                                                       float("inf")))
    w.before(0.5, True, 3.0, cfg)
    assert w.after(0.0) == (True, 1.2)  # entered: the slowest of the approach
    assert w.slowest == float("inf")  # and forgotten
    w.before(3.0, False, 0.5, cfg)  # a junction without give-way control: nothing kept
    assert w.after(0.0) == (False, float("inf"))
    w.before(3.0, True, 0.5, cfg)
    w.reset()
    assert w.slowest == float("inf") and w.after(0.0) == (False, float("inf"))
