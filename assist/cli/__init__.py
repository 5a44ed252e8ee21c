"""cli: the ``ptw-assist`` program, the top of the stack.

One module per command family: ``control`` (design, evaluate, demo, observability), ``diagnose``,
``estimate``, ``risk``, ``rl`` (train-rl). Importing this package imports them, so that their
commands register in :mod:`ptw_env.cli`'s registry beside the simulator's own; :func:`main` then
runs :func:`ptw_env.cli.main`. The console script ``ptw-assist`` and ``python -m assist.cli`` point
here.

May import: every family of ``assist`` and ``ptw_env``. Nothing in the library imports it
(``tests/test_architecture.py``).

Example::

    >>> from assist.cli import build_parser
    >>> build_parser().parse_args(["design", "--vmin", "8", "--vmax", "33"]).command
    'design'
"""

from __future__ import annotations

import argparse
from typing import Sequence

import ptw_env.cli

from assist.cli import control, diagnose, estimate, risk, rl  # noqa: F401  (each registers its commands)


def build_parser() -> argparse.ArgumentParser:
    """The parser of the whole program (every registered command)."""
    return ptw_env.cli.build_parser()


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``ptw-assist`` with ``argv`` (default ``sys.argv[1:]``); returns the exit status
    (:func:`ptw_env.cli.main`)."""
    return ptw_env.cli.main(argv)


__all__ = ["build_parser", "main"]

