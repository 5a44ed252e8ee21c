"""Moved to :mod:`assist.estimation.adaptive_design`; this path re-exports it for one release (DeprecationWarning)."""

import warnings as _warnings
from typing import Any as _Any

from assist.estimation import adaptive_design as _new
from assist.estimation.adaptive_design import *  # noqa: F401,F403

_warnings.warn("assist.adaptive_design moved to assist.estimation.adaptive_design; the old path goes in the next release",
               DeprecationWarning, stacklevel=2)


def __getattr__(name: str) -> _Any:  # every other name of the module, as before (PEP 562)
    return getattr(_new, name)
