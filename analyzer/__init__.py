"""The offline analyzer: reads clips, learns models, writes tile databases."""
from __future__ import annotations

from .video import Clip, ClipError, load_clip

__all__ = ["Clip", "ClipError", "load_clip"]
