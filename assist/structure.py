"""Moved to :mod:`assist.unknown_input.structure`; this path re-exports it for one release (DeprecationWarning)."""

import warnings as _warnings
from typing import Any as _Any

from assist.unknown_input import structure as _new
from assist.unknown_input.structure import *  # noqa: F401,F403

_warnings.warn("assist.structure moved to assist.unknown_input.structure; the old path goes in the next release",
               DeprecationWarning, stacklevel=2)


def __getattr__(name: str) -> _Any:  # every other name of the module, as before (PEP 562)
    return getattr(_new, name)
