"""Where derived area data (ground truth) is cached on disk."""

from __future__ import annotations

import os
from pathlib import Path

CACHE_ENV = "FLYBO_CACHE_DIR"


def cache_dir() -> Path:
    """Root of the flybo disk cache: ``$FLYBO_CACHE_DIR`` if set, else ``~/.cache/flybo``."""
    configured = os.environ.get(CACHE_ENV)
    if configured:
        return Path(configured).expanduser()
    return Path.home() / ".cache" / "flybo"
