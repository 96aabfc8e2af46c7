"""The user's cache folder of dynatex: where what is worth keeping between runs lives.

The OpenCL self-test's device verdicts (``devices.json``) and the databases that passed the
probe (``databases.json``) are kept there, so a game pays each once per machine, driver and file.
A leaf: the tile database and the player both use it.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

__all__ = ["cache_dir"]


def cache_dir() -> Path:
    """The user's cache folder of dynatex: ``$DYNATEX_CACHE_DIR``, else the platform's
    (``$XDG_CACHE_HOME/dynatex``, ``~/.cache/dynatex``; ``~/Library/Caches/dynatex`` on macOS;
    ``%LOCALAPPDATA%\\dynatex`` on Windows)."""
    root = os.environ.get("DYNATEX_CACHE_DIR")
    if root:
        return Path(root)
    if sys.platform == "win32":
        base = Path(os.environ.get("LOCALAPPDATA", Path.home() / "AppData" / "Local"))
    elif sys.platform == "darwin":
        base = Path.home() / "Library" / "Caches"
    else:
        base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return base / "dynatex"
