"""Shared fixtures: where the real DVL recordings live.

The recordings are in the project's shared folder (``../shared/data/real`` next to the
checkout). Set UNDERTOW_REAL_DATA to point elsewhere.
"""

import os
from pathlib import Path


def _find_real_data() -> Path:
    env = os.environ.get("UNDERTOW_REAL_DATA")
    if env:
        return Path(env)
    here = Path(__file__).resolve().parent
    for parent in here.parents:
        candidate = parent / "shared" / "data" / "real"
        if candidate.is_dir():
            return candidate
    return Path("/work/shared/data/real")


REAL_DATA = _find_real_data()
