"""Moved to :mod:`assist.cli.diagnose`; this path re-exports it for one release (DeprecationWarning)."""

import warnings as _warnings
from typing import Any as _Any

from assist.cli import diagnose as _new
from assist.cli.diagnose import *  # noqa: F401,F403

_warnings.warn("assist.diagnose_cli moved to assist.cli.diagnose; the old path goes in the next release",
               DeprecationWarning, stacklevel=2)


def __getattr__(name: str) -> _Any:  # every other name of the module, as before (PEP 562)
    return getattr(_new, name)
