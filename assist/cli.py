"""The ``ptw-assist`` program: the top of the stack.

Imports the command modules of :mod:`assist` (``design``, ``evaluate``,
``demo``, ``observability``, ``diagnose``, ``estimate``, ``risk``,
``train-rl``) so that they register in :mod:`ptw_env.cli`'s registry beside
the simulator's own commands, then runs :func:`ptw_env.cli.main`. No library
module imports this one (``tests/test_architecture.py``); the console script
``ptw-assist`` points here.

Example::

    >>> from assist.cli import build_parser
    >>> build_parser().parse_args(["design", "--vmin", "8", "--vmax", "33"]).command
    'design'
"""

from __future__ import annotations

import argparse
from typing import Sequence

import ptw_env.cli

from . import commands, diagnose_cli, estimate_cli, risk_cli, rl_cli  # noqa: F401  (each registers its commands)


def build_parser() -> argparse.ArgumentParser:
    """The parser of the whole program (every registered command)."""
    return ptw_env.cli.build_parser()


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``ptw-assist`` with ``argv`` (default ``sys.argv[1:]``); returns the exit status
    (:func:`ptw_env.cli.main`)."""
    return ptw_env.cli.main(argv)


__all__ = ["build_parser", "main"]


if __name__ == "__main__":  # pragma: no cover  (python -m assist.cli)
    raise SystemExit(main())
