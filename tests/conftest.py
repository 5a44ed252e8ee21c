"""Shared test configuration: where the project's shared/ folder (specs, reference logs) is."""

from __future__ import annotations

import os
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _shared_dir() -> Path:
    """``$PTW_SHARED_DIR``, else ``shared/`` beside the repository (as CI lays it out), else /work/shared."""
    cands = [os.environ.get("PTW_SHARED_DIR"), ROOT.parent / "shared", Path("/work/shared")]
    for c in cands:
        if c and (Path(c) / "data").is_dir():
            return Path(c)
    return ROOT.parent / "shared"


SHARED = _shared_dir()
DATA = SHARED / "data"
