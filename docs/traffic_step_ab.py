"""Old and new ``World.step`` in one process: the same states, CPU time alternately.

Times a copy of an older ``dstenv`` (renamed ``dstenv_old``) against the current one
on the default city (the world of ``dstenv generate``'s default scenario), in turns, in
one process: separate processes on a shared VM differ by more than the change. First
it checks that both step the same traffic: for each seed, ``--steps`` steps of both
worlds from the same seed, every state array equal bit for bit. Then it times blocks
of 200 steps of each in turn (thread CPU time) and prints the median and the minimum
per step::

    mkdir -p /tmp/old && git archive OLD dstenv | tar -x -C /tmp/old   # OLD: a commit
    cd /tmp/old && mv dstenv dstenv_old
    grep -rl dstenv dstenv_old --include=*.py | xargs sed -i 's/\\bdstenv\\b/dstenv_old/g'
    cd /tmp && PYTHONPATH=/path/to/dstenv python /path/to/dstenv/docs/traffic_step_ab.py \\
        /tmp/old --seeds 3 --steps 300 --rounds 15

(``docs/throughput.md``, section 4, used OLD = 6715ce8 for the traffic step's reach
test, ``bbed445``.)
"""

import argparse
import statistics
import sys
import time


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("old", help="folder holding the dstenv_old package")
    ap.add_argument("--seeds", type=int, default=3, help="seeds checked for equal states")
    ap.add_argument("--steps", type=int, default=300, help="steps per seed checked")
    ap.add_argument("--rounds", type=int, default=15, help="timed blocks of each")
    args = ap.parse_args()
    sys.path.insert(0, args.old)

    import numpy as np

    from dstenv.pipeline import default_config
    from dstenv.sim.world import World
    from dstenv_old.pipeline import default_config as old_default_config
    from dstenv_old.sim.world import World as OldWorld

    def worlds(seed: int) -> tuple:
        return (OldWorld(old_default_config()["world"], seed=seed),
                World(default_config()["world"], seed=seed))

    for seed in range(args.seeds):
        old, new = worlds(seed)
        for _ in range(args.steps):
            old.step()
            new.step()
        same = all(np.array_equal(old._state[k], new._state[k]) for k in new._state)
        print(f"seed {seed}: {args.steps} steps, every state array equal: {same}")
        if not same:
            raise SystemExit("the two versions step different traffic")
    old, new = worlds(0)
    for w in (old, new):  # compilation, caches
        for _ in range(50):
            w.step()
    us: dict[str, list[float]] = {"old": [], "new": []}
    for _ in range(args.rounds):
        for name, w in (("old", old), ("new", new)):
            t0 = time.thread_time()
            for _ in range(200):
                w.step()
            us[name].append(1e6 * (time.thread_time() - t0) / 200)
    for name, v in us.items():
        print(f"{name}: median {statistics.median(v):.1f} us CPU per step, "
              f"minimum {min(v):.1f} ({args.rounds} blocks of 200 steps)")
    print(f"new / old (medians): {statistics.median(us['new']) / statistics.median(us['old']):.3f}")


if __name__ == "__main__":
    main()
