"""Moved to :mod:`assist.estimation.identifiability`; this path re-exports it for one release (DeprecationWarning)."""

import warnings as _warnings
from typing import Any as _Any

from assist.estimation import identifiability as _new
from assist.estimation.identifiability import *  # noqa: F401,F403

_warnings.warn("assist.identifiability moved to assist.estimation.identifiability; the old path goes in the next release",
               DeprecationWarning, stacklevel=2)


def __getattr__(name: str) -> _Any:  # every other name of the module, as before (PEP 562)
    return getattr(_new, name)
