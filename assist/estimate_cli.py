"""Moved to :mod:`assist.cli.estimate`; this path re-exports it for one release (DeprecationWarning)."""

import warnings as _warnings
from typing import Any as _Any

from assist.cli import estimate as _new
from assist.cli.estimate import *  # noqa: F401,F403

_warnings.warn("assist.estimate_cli moved to assist.cli.estimate; the old path goes in the next release",
               DeprecationWarning, stacklevel=2)


def __getattr__(name: str) -> _Any:  # every other name of the module, as before (PEP 562)
    return getattr(_new, name)
