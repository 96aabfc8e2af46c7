"""The offline analyzer: reads clips, learns models, writes tile databases."""

from __future__ import annotations

from .corpus import ClipResult, analyze_corpus, format_table
from .errors import ClipError, SchedulerError
from .metrics import (
    frame_coverage,
    patch_distances,
    repetition_lag,
    seam_visibility,
    spectrum_distance,
    stability,
    temporal_discontinuity,
)
from .video import Clip, load_clip

__all__ = ["Clip", "ClipError", "ClipResult", "SchedulerError", "analyze_corpus", "format_table", "load_clip"]
__all__ += [
    "frame_coverage",
    "patch_distances",
    "repetition_lag",
    "seam_visibility",
    "spectrum_distance",
    "stability",
    "temporal_discontinuity",
]
