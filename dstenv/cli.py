"""The ``dstenv`` command.

Each subcommand lives next to the code it drives; a module listed in
:data:`COMMANDS` exposes ``register(subparsers)`` that adds its parser(s) and sets
``func`` (a callable taking the parsed namespace and returning an exit code).
Modules are imported only when the command line is parsed, so ``dstenv --version``
stays fast.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

from dstenv import __version__

__all__ = ["COMMANDS", "build_parser", "main"]

#: Modules that contribute subcommands, in ``--help`` order.
COMMANDS: tuple[str, ...] = (
    "dstenv.data.cli",  # generate, info
    "dstenv.segment.cli",  # train, benchmark
    "dstenv.kitti.cli",  # kitti convert
    "dstenv.sim.cli",  # render
    "dstenv.bench",  # bench
)


class CLIError(Exception):
    """A user-facing error: printed as one line, exit status 2."""


def build_parser() -> argparse.ArgumentParser:
    """The full argument parser, with every available subcommand."""
    parser = argparse.ArgumentParser(
        prog="dstenv",
        description="Dempster-Shafer perception grids: simulate, generate data, benchmark.",
    )
    parser.add_argument("--version", action="version", version=f"dstenv {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMANDS:
        importlib.import_module(name).register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``dstenv`` console script; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 0
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        print("dstenv: interrupted", file=sys.stderr)
        return 130
    except CLIError as exc:
        print(f"dstenv {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except Exception as exc:  # noqa: BLE001 - user-facing boundary
        from dstenv.config import ConfigError

        if isinstance(exc, (ConfigError, FileNotFoundError, PermissionError, ValueError, OSError)):
            print(f"dstenv {args.command}: error: {exc}", file=sys.stderr)
            return 2
        raise


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
