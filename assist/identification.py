"""Moved to :mod:`assist.estimation.identification`; this path re-exports it for one release (DeprecationWarning)."""

import warnings as _warnings
from typing import Any as _Any

from assist.estimation import identification as _new
from assist.estimation.identification import *  # noqa: F401,F403

_warnings.warn("assist.identification moved to assist.estimation.identification; the old path goes in the next release",
               DeprecationWarning, stacklevel=2)


def __getattr__(name: str) -> _Any:  # every other name of the module, as before (PEP 562)
    return getattr(_new, name)
