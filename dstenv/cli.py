"""The ``dstenv`` command.

Each subcommand lives next to the code it drives: the module named for it in
:data:`COMMANDS` exposes ``register(subparsers)``, which adds its parser(s) and
sets ``func`` (a callable taking the parsed namespace and returning an exit code).
Only the module of the command being run is imported; ``dstenv --help`` lists
every command from the one-line help in :data:`COMMANDS`, so ``dstenv --version``
and ``dstenv --help`` import neither torch, scipy, numba nor any subsystem.

Errors: a :class:`~dstenv.config.CLIError`, :class:`~dstenv.config.ConfigError`
or an expected OS error (missing file, permission, disk full) is printed as one
line naming the problem, with exit status 2; anything else is a bug and keeps its
traceback.
"""

from __future__ import annotations

import argparse
import difflib
import importlib
import os
import re
import sys
from collections.abc import Sequence
from typing import Any, NoReturn

from dstenv import __version__
from dstenv.config import CLIError

__all__ = ["COMMANDS", "CLIError", "build_parser", "main", "plain"]

#: command -> (module that registers it, one-line help), in ``--help`` order.
COMMANDS: dict[str, tuple[str, str]] = {
    "generate": ("dstenv.data.cli", "generate labelled frames as HDF5 shards"),
    "info": ("dstenv.data.cli", "describe a shard dataset"),
    "train": ("dstenv.segment.cli", "train a segmentation network on shards or a stream"),
    "benchmark": ("dstenv.segment.bench_cli",
                  "compare DST and FCN-DST segmenters on held-out maps"),
    "kitti": ("dstenv.kitti.cli", "KITTI tracking -> perception-grid shards"),
    "export-kitti": ("dstenv.kitti.cli", "simulate a drive with the 3-D LIDAR, write it in "
                     "KITTI's tracking layout"),
    "render": ("dstenv.sim.cli", "draw a simulated scene to PNG"),
    "bench": ("dstenv.bench", "run a speed benchmark"),
}


def plain(doc: str | None) -> str:
    """A module docstring as ``--help`` text: RST roles and literals as plain words."""
    text = re.sub(r":[a-z]+:`~?([^`]+)`", r"\1", doc or "").replace("``", "")
    return re.sub(r"\n::\n", "\n", text)  # a literal block's marker line


def _command_of(argv: Sequence[str]) -> str | None:
    """The subcommand named on the command line (the first non-option word)."""
    for word in argv:
        if not word.startswith("-"):
            return word if word in COMMANDS else None
    return None


class Parser(argparse.ArgumentParser):
    """argparse with one-line errors: the command's name, the problem, a close option
    for a typo, and where the usage is (argparse printed the whole usage first, and an
    unknown option of a subcommand was reported under the top-level usage)."""

    words: list[str] = []

    def parse_known_args(self, args: Any = None, namespace: Any = None) -> Any:  # noqa: D102
        self.words = [str(a) for a in (sys.argv[1:] if args is None else args)]
        return super().parse_known_args(args, namespace)

    def error(self, message: str) -> NoReturn:  # noqa: D102 - argparse's hook
        self.exit(2, f"{self.prog}: error: {message}{typo_hint(self, message)} "
                     f"(see {self.prog} --help)\n")


def typo_hint(parser: Parser, message: str) -> str:
    """``; did you mean --x?`` for the first option word no option of ``parser``
    has (from an "unrecognized arguments" message, else from the words it parsed: a
    misspelt required option is reported as missing first) with a close match."""
    known = [o for a in parser._actions for o in a.option_strings]  # noqa: SLF001
    unknown = (message.split(":", 1)[1].split() if message.startswith("unrecognized")
               else parser.words)
    for word in unknown:
        name = word.split("=")[0]
        if not name.startswith("--") or any(k.startswith(name) for k in known):
            continue  # (a prefix of an option is argparse's own abbreviation)
        close = difflib.get_close_matches(name, known, n=1, cutoff=0.7)
        if close:
            lead = "" if message.startswith("unrecognized") else f" ({name} is no option)"
            return f"{lead}; did you mean {close[0]}?"
    return ""


def _chosen(parser: argparse.ArgumentParser, args: argparse.Namespace
            ) -> argparse.ArgumentParser:
    """The (sub)parser of the command that ``args`` ran (``dstenv kitti convert``'s)."""
    for action in parser._actions:  # noqa: SLF001 - argparse keeps subparsers there
        if isinstance(action, argparse._SubParsersAction):  # noqa: SLF001
            name = getattr(args, action.dest, None)
            if name in action.choices:
                return _chosen(action.choices[name], args)
    return parser


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The argument parser; only ``command``'s module is imported (all when ``"*"``).

    Commands whose module is not imported get a placeholder parser that carries
    their one-line help, so ``--help`` lists every command.
    """
    parser = Parser(
        prog="dstenv",
        description="Dempster-Shafer perception grids: simulate, generate data, benchmark.",
    )
    parser.add_argument("--version", action="version", version=f"dstenv {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    modules = {m for m, _ in COMMANDS.values()} if command == "*" else (
        {COMMANDS[command][0]} if command in COMMANDS else set())
    for name in dict.fromkeys(m for m, _ in COMMANDS.values()):
        if name in modules:
            importlib.import_module(name).register(sub)
    for name, (_, help_text) in COMMANDS.items():
        if name not in sub.choices:
            sub.add_parser(name, help=help_text)
    return parser


#: commands that write nothing until they finish (an interrupted one has nothing to resume)
UNRESUMABLE = frozenset({"info", "render", "bench"})

#: errors a command reports as one line (``ConfigError`` is a ``ValueError``; missing
#: files, permissions and a full disk are ``OSError``s); anything else is a bug
EXPECTED_ERRORS: tuple[type[BaseException], ...] = (CLIError, ValueError, OSError, MemoryError)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``dstenv`` console script; returns the exit status."""
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser(_command_of(argv))
    args, extra = parser.parse_known_args(argv)
    if extra:  # reported by the command that was given them, not by dstenv's top level
        _chosen(parser, args).error(f"unrecognized arguments: {' '.join(extra)}")
    if not getattr(args, "func", None):
        parser.print_help()
        return 0
    from dstenv.data.lifeline import sigterm_as_interrupt

    try:
        with sigterm_as_interrupt():  # every command: SIGTERM (docker stop, SLURM) cleans up
            return int(args.func(args) or 0)  # like Ctrl-C (a kill left locks, partials)
    except KeyboardInterrupt as exc:  # Ctrl-C, or SIGTERM where a command turned it into one
        terminated = type(exc).__name__ == "Terminated"
        kept = ("; finished work is kept, rerun the same command to resume"
                if args.command not in UNRESUMABLE else "; nothing to resume: rerun the command")
        print(f"dstenv: {'terminated' if terminated else 'interrupted'}{kept}", file=sys.stderr)
        return 143 if terminated else 130
    except BrokenPipeError:  # the reader of stdout went away (dstenv info ... | head)
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no error at exit
        return 141  # as a shell reports SIGPIPE
    except EXPECTED_ERRORS as exc:
        print(f"dstenv {args.command}: error: {one_line(exc)}", file=sys.stderr)
        return 2


def one_line(exc: BaseException) -> str:
    """The one-line message of an expected error (also the baselines' scripts')."""
    if isinstance(exc, MemoryError):
        return "out of memory; use a smaller grid, fewer frames per shard or fewer workers"
    if isinstance(exc, OSError) and exc.filename and exc.strerror:
        return f"{exc.filename}: {exc.strerror}"
    text = str(exc) or type(exc).__name__
    if "Traceback (most recent call last)" in text:
        # an error re-raised from a worker (torch's DataLoader embeds the worker's whole
        # traceback in the message): its last line is the worker's own error
        head = text.strip().splitlines()[0]
        last = [ln for ln in text.strip().splitlines() if ln.strip()][-1]
        return f"{' '.join(head.split())} {last.strip()}"
    return " ".join(text.split())


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
