"""Moved to :mod:`assist.control.lqg`; this path re-exports it for one release (DeprecationWarning)."""

import warnings as _warnings
from typing import Any as _Any

from assist.control import lqg as _new
from assist.control.lqg import *  # noqa: F401,F403

_warnings.warn("assist.lqg moved to assist.control.lqg; the old path goes in the next release",
               DeprecationWarning, stacklevel=2)


def __getattr__(name: str) -> _Any:  # every other name of the module, as before (PEP 562)
    return getattr(_new, name)
