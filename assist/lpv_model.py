"""Moved to :mod:`assist.estimation.lpv_model`; this path re-exports it for one release (DeprecationWarning)."""

import warnings as _warnings
from typing import Any as _Any

from assist.estimation import lpv_model as _new
from assist.estimation.lpv_model import *  # noqa: F401,F403

_warnings.warn("assist.lpv_model moved to assist.estimation.lpv_model; the old path goes in the next release",
               DeprecationWarning, stacklevel=2)


def __getattr__(name: str) -> _Any:  # every other name of the module, as before (PEP 562)
    return getattr(_new, name)
