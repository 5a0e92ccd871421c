"""``dstenv render``: a top view of a world (map, agents, ego, LIDAR sweep) as PNG."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import numpy as np

from dstenv import palette
from dstenv.io import atomic_path

__all__ = ["register", "render_png", "draw_world", "draw_legend", "LEGEND"]

#: colours of surface and map-class codes, ``[0, 1]`` floats (:mod:`dstenv.palette`)
SURFACE_RGB = palette.as_float(palette.SURFACE_RGB)
MAPCLASS_RGB = palette.as_float(palette.MAPCLASS_RGB)


def draw_world(ax: Any, world: Any, sweep: Any = None, extent: float | None = None,
               lanes: bool = False) -> None:
    """Draw a :class:`dstenv.sim.World` on a matplotlib axis (world frame, metres).

    Moving agents are red (cars), orange (cyclists) or magenta (pedestrians);
    static ones (parked or stopped) blue; the ego green; LIDAR returns yellow.
    """
    from matplotlib.collections import LineCollection, PolyCollection

    from dstenv.sim.raster import surface_raster

    wm = world.map
    x0, x1, y0, y1 = wm.bounds
    surface = surface_raster(wm)
    rgb = SURFACE_RGB[surface] if surface is not None else MAPCLASS_RGB[wm.raster]
    ax.imshow(rgb, origin="lower", extent=(x0, x1, y0, y1), interpolation="nearest")
    if lanes and wm.lanes is not None:
        net = wm.lanes
        segs = [net.polyline(k) for k in range(len(net))]
        ax.add_collection(LineCollection(segs, colors="w", linewidths=0.3, alpha=0.6))
    from dstenv.sim.types import ObstacleKind

    obs = world.map.obstacles
    if len(obs):
        # clutter: ground-standing boxes dark olive, tree crowns translucent green on top
        crown = obs.kind == ObstacleKind.TREE_CROWN
        panel = obs.z_min > 1.0
        ground_rgb, crown_rgb = palette.as_float(palette.CLUTTER_RGB)
        ax.add_collection(PolyCollection(obs.corners()[~panel], facecolors=[ground_rgb],
                                         edgecolors="none"))
        ax.add_collection(PolyCollection(obs.corners()[crown], facecolors=[crown_rgb],
                                         edgecolors="none", alpha=0.25))
    ag = world.agents
    if len(ag):
        moving = ag.speed > 0.1
        colours = np.array(["#d62728", "#ff7f0e", "#e377c2"])[ag.kind]
        colours = np.where(moving, colours, "#1f3fbf")
        ax.add_collection(PolyCollection(ag.corners(), facecolors=colours, edgecolors="k",
                                         linewidths=0.3))
    x, y, yaw = world.ego_pose
    length, width = world.ego_size
    from dstenv.sim.ego import box_corners

    ax.add_collection(PolyCollection([box_corners(x, y, yaw, length, width)],
                                     facecolors="#2ca02c", edgecolors="k", linewidths=0.5))
    if sweep is not None:
        c, s = np.cos(yaw), np.sin(yaw)
        p = sweep.points[sweep.hit]
        wx, wy = x + c * p[:, 0] - s * p[:, 1], y + s * p[:, 0] + c * p[:, 1]
        ax.plot([x], [y], "g+", ms=8)
        ax.scatter(wx, wy, s=0.6, c="#ffd700", lw=0)
    if extent is not None:
        ax.set_xlim(x - extent, x + extent)
        ax.set_ylim(y - extent, y + extent)
    else:
        ax.set_xlim(x0, x1)
        ax.set_ylim(y0, y1)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")


#: legend of :func:`draw_world`: (label, face colour) of what it draws
LEGEND: tuple[tuple[str, Any], ...] = (
    ("road", SURFACE_RGB[2]), ("sidewalk", SURFACE_RGB[3]), ("parking strip", SURFACE_RGB[4]),
    ("building", SURFACE_RGB[1]), ("yard / open", SURFACE_RGB[0]),
    ("median / island", SURFACE_RGB[6]),
    ("moving car", "#d62728"), ("moving cyclist", "#ff7f0e"),
    ("moving pedestrian", "#e377c2"), ("static agent (parked, stopped)", "#1f3fbf"),
    ("ego", "#2ca02c"),
)


def draw_legend(ax: Any, lidar: bool = True) -> None:
    """A legend of :data:`LEGEND` (plus the LIDAR returns) beside the axis, right of it
    (inside, it hid the top-right corner of the map)."""
    from matplotlib.patches import Patch

    handles = [Patch(facecolor=c, edgecolor="k", linewidth=0.3, label=t) for t, c in LEGEND]
    if lidar:
        handles.append(Patch(facecolor="#ffd700", label="LIDAR return"))
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=7,
              borderaxespad=0.0)


def render_png(world: Any, out: str | Path, sweep: Any = None, extent: float | None = None,
               title: str = "", lanes: bool = False, dpi: int = 150) -> Path:
    """Write a top view of ``world`` to ``out`` (atomically: temp file, then rename)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out)
    fig, ax = plt.subplots(figsize=(11, 9))
    draw_world(ax, world, sweep, extent, lanes)
    ax.set_title(title)
    draw_legend(ax, sweep is not None)
    fig.tight_layout()
    try:
        with atomic_path(out) as tmp:
            fig.savefig(tmp, dpi=dpi, format="png")
    finally:
        plt.close(fig)
    return out


def _cmd(args: argparse.Namespace) -> int:
    from dstenv.config import build_config
    from dstenv.data.cli import parse_set
    from dstenv.io import png_path
    from dstenv.scenario_files import scenario_path
    from dstenv.sim import World

    from dstenv.config import CLIError

    png_path(args.out)  # before the simulation, not after
    if not 0 <= args.seed < 2**63:
        raise CLIError(f"--seed must be in [0, 2**63), got {args.seed}")
    if not 0 <= args.steps <= 100_000:
        raise CLIError(f"--steps must be in 0..100000 (0.1 s each), got {args.steps}")
    if not (np.isfinite(args.extent) and 0 <= args.extent <= 100_000):  # 1e308: NaN axes
        raise CLIError(f"--extent must be a size in metres in [0, 100000] (0: the whole "
                       f"map), got {args.extent}")
    path = scenario_path(args.scenario)
    over = parse_set(args.set or [])
    unused = [k for k in over if k not in ("source", "world", "lidar")]
    if unused:  # accepted and then ignored, it would draw something else than asked
        raise CLIError(f"--set {unused[0]}...: render draws the world and its 2-D LIDAR sweep "
                       f"and uses no {unused[0]} settings; set world or lidar keys only")
    cfg = build_config(path, ("--set", over))
    if cfg["source"] != "city":  # what this command draws: the city world, the 2-D sweep
        raise CLIError(f"render draws the city world; source = {cfg['source']!r} is not "
                       "drawn (a highway-env scene: gym.make('DSTGrid-Highway-v0', "
                       "render_mode='rgb_array'))")
    if cfg["lidar"]["model"] != "2d" and not args.no_lidar:
        raise CLIError(f"render draws the 2-D LIDAR's sweep; lidar.model = "
                       f"{cfg['lidar']['model']!r} is not drawn: add --no-lidar, or look at its "
                       "scans with dstenv export-kitti then dstenv kitti render")
    world = World(cfg["world"], seed=args.seed, base_dir=path.parent)
    for _ in range(args.steps):
        world.step()
    sweep = None
    if not args.no_lidar:
        try:
            from dstenv.sensing import Lidar
        except ImportError:  # sensing not part of this build
            Lidar = None
        if Lidar is not None:
            sweep = Lidar(cfg["lidar"]).sweep(world.map, world.agents, world.ego_pose,
                                           np.random.default_rng(args.seed))
    extent = None if args.extent <= 0 else args.extent
    title = f"{path.stem}  seed {args.seed}  t = {world.time:.1f} s"
    out = render_png(world, args.out, sweep, extent, title, lanes=args.lanes)
    print(f"wrote {out}")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``dstenv render`` to the CLI."""
    from dstenv.cli import plain

    p = sub.add_parser("render", help="draw a simulated scene to PNG",
                       description=plain(__doc__))
    p.add_argument("--scenario", default="default", metavar="NAME|FILE",
                   help="scenario name or .toml file (default: default)")
    p.add_argument("--seed", type=int, default=0, help="episode seed (default 0)")
    p.add_argument("--out", required=True, help="PNG file to write")
    p.add_argument("--steps", type=int, default=0,
                   help="world steps of 0.1 s before drawing (default 0)")
    p.add_argument("--extent", type=float, default=0.0,
                   help="half width of the view around the ego [m] (0: whole map)")
    p.add_argument("--lanes", action="store_true", help="draw lane centre-lines")
    p.add_argument("--no-lidar", action="store_true", help="do not draw the LIDAR sweep")
    p.add_argument("--set", action="append", metavar="SECTION.KEY=VALUE",
                   help="override a world or lidar value (TOML value), repeatable, as in "
                        "generate; the city world and the 2-D sweep are drawn")
    p.set_defaults(func=_cmd)
