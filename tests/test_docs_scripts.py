"""Every script in ``docs/`` answers ``--help`` (argparse, or its docstring) instead of
running or crashing on it: the README quotes their commands."""

from pathlib import Path

import pytest

DOCS = Path(__file__).resolve().parents[1] / "docs"


@pytest.mark.parametrize("script", sorted(p.name for p in DOCS.glob("*.py")))
def test_docs_script_handles_help(script):
    text = (DOCS / script).read_text()
    assert ("argparse" in text or "parse_args(" in text
            or "nets_args(" in text  # seed_choice.py's argparse, shared by calibrated_free.py
            or '{"-h", "--help"} & set(sys.argv[1:])' in text), (
        f"docs/{script}: give it argparse, or the docstring guard for --help")
