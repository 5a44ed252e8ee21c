"""Moved to :mod:`assist.control.ts_model`; this path re-exports it for one release (DeprecationWarning)."""

import warnings as _warnings
from typing import Any as _Any

from assist.control import ts_model as _new
from assist.control.ts_model import *  # noqa: F401,F403

_warnings.warn("assist.ts_model moved to assist.control.ts_model; the old path goes in the next release",
               DeprecationWarning, stacklevel=2)


def __getattr__(name: str) -> _Any:  # every other name of the module, as before (PEP 562)
    return getattr(_new, name)
