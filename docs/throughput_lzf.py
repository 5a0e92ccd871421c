"""lzf vs gzip (ISA-L level 1): bytes per frame and ShardWriter CPU, same process.

Real stride-10 frames at 256 x 256 (3 episodes of 19 frames per scenario), bytes per
frame of each episode's shard, and the writer's thread CPU per frame (median of 9
alternating runs over 32 frames, opening and committing the shard included).
Figures in docs/throughput.md, section 1 (third pass).

    python docs/throughput_lzf.py default dense
"""

import sys

if __name__ == "__main__" and {"-h", "--help"} & set(sys.argv[1:]):  # usage: the docstring
    print(__doc__)
    raise SystemExit(0)

import statistics
import sys
import tempfile
import time
from itertools import islice
from pathlib import Path

from dstenv.data.sampling import episode_seeds, iter_frames, scenario_config
from dstenv.data.shards import ShardWriter
from dstenv.pipeline import Pipeline

SETTINGS = {"gzip-isal1": {"compression": "gzip", "compression_opts": 1},
            "lzf": {"compression": "lzf", "compression_opts": None}}


def write(path: Path, attrs: dict, frames: list, **kw) -> None:
    with ShardWriter(path, attrs, **kw) as w:
        for f in frames:
            w.add(f)


def main(scenarios: list[str]) -> None:
    tmp = Path(tempfile.mkdtemp())
    for scen in scenarios:
        cfg = scenario_config(None if scen == "default" else scen, {})
        episodes = [  # one episode per map seed: 200 steps, stride 10, warm-up 10
            list(islice(iter_frames(lambda: Pipeline(cfg), episode_seeds(11 + k, "train", (0,)),
                                    200, 10, 10), 19))
            for k in range(3)]
        attrs = {"config": cfg, "seed": 0}
        for kw in SETTINGS.values():  # numba compilation, imports
            write(tmp / "warm.h5", attrs, episodes[0][:2], **kw)
        for k, frames in enumerate(episodes):
            sizes = []
            for name, kw in SETTINGS.items():
                write(tmp / f"{name}.h5", attrs, frames, **kw)
                kb = (tmp / f"{name}.h5").stat().st_size / len(frames) / 1e3
                sizes.append(f"{name} {kb:.1f}")
            print(f"{scen} episode {k} ({len(frames)} frames), KB/frame:", ", ".join(sizes))
        frames = [f for fs in episodes for f in fs][:32]
        times: dict[str, list[float]] = {k: [] for k in SETTINGS}
        for _ in range(9):
            for name, kw in SETTINGS.items():
                c = time.thread_time()
                write(tmp / "t.h5", attrs, frames, **kw)
                times[name].append((time.thread_time() - c) / len(frames) * 1e3)
        print(f"{scen} writer CPU ms/frame:",
              {k: round(statistics.median(v), 3) for k, v in times.items()})


if __name__ == "__main__":
    main(sys.argv[1:] or ["default", "dense"])
