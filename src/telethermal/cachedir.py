"""The user's cache folder: what telethermal computes once and keeps
across processes (idle policies, the effusivity estimator's curves)."""

from __future__ import annotations

import os
from pathlib import Path

#: The environment variable naming the cache folder (tests set it to a
#: temporary folder: the suite never writes into the user's home).
CACHE_ENV = "TELETHERMAL_CACHE"


def cache_dir() -> Path:
    """``$TELETHERMAL_CACHE``, else ``$XDG_CACHE_HOME/telethermal``, else
    ``~/.cache/telethermal`` (not created here)."""
    own = os.environ.get(CACHE_ENV)
    if own:
        return Path(own)
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "telethermal"
