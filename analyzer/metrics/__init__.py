"""Objective quality measures for synthesized dynamic textures.

Every function takes clips as arrays ``(T, H, W)`` or ``(T, H, W, C)`` (uint8, or floats on
the 0..255 scale; ``C`` is 1 or 3) and keyword-only options. See ``analyzer/METRICS.md``
for the definition, units, range and good/bad values of each measure. One module per family:

- Long-run stability (:mod:`.longrun`): :func:`stability` (energy ratio per time window, NaN/inf count).
- Seams in space and time (:mod:`.seams`): :func:`seam_visibility` with :func:`grid_labels`;
  temporal discontinuity: :func:`temporal_discontinuity`, :func:`frame_step_ratio`.
- Likeness to the source (:mod:`.likeness`): :func:`spectrum_distance` (:func:`st_power_spectrum`),
  :func:`patch_coherence`, :func:`patch_completeness` (both at once: :func:`patch_distances`).
- Double images, a crossfade showing two objects (:mod:`.ghosts`): :func:`double_image`,
  :func:`double_image_level` (the source's own level), :func:`crossfade_double_image`;
  structure the source never shows at that place: :func:`local_novelty`.
- Coverage and repetition in time (:mod:`.repetition`): :func:`frame_coverage`, :func:`index_coverage`,
  :func:`repetition_lag` (:func:`repetition_profile`).
- Repetition in space (:mod:`.lattice`): :func:`lattice_prominence` (a cell lattice standing out),
  :func:`lattice_correlation`.
- Colours the source never had (:mod:`.gamut`): :func:`out_of_gamut_share`, calibrated by
  :func:`source_gamut_share`; in places that never had them: :func:`local_out_of_gamut_share`,
  calibrated by :func:`source_local_gamut_share`.
- All of them at once (:mod:`.report`): :func:`evaluate`.
"""

from __future__ import annotations

from ...checks import check_frames
from .gamut import (
    GAMUT_BITS,
    colour_set,
    local_out_of_gamut_share,
    out_of_gamut_share,
    source_gamut_share,
    source_local_gamut_share,
)
from .ghosts import DoubleImages, crossfade_double_image, double_image, double_image_level, local_novelty
from .lattice import lattice_correlation, lattice_lags, lattice_prominence
from .likeness import patch_coherence, patch_completeness, patch_distances, spectrum_distance, st_power_spectrum
from .longrun import StabilityReport, count_nonfinite, stability
from .repetition import frame_coverage, index_coverage, repetition_lag, repetition_profile
from .report import evaluate
from .seams import frame_step_ratio, grid_labels, seam_visibility, temporal_discontinuity

__all__ = [
    "GAMUT_BITS",
    "DoubleImages",
    "StabilityReport",
    "check_frames",
    "colour_set",
    "count_nonfinite",
    "crossfade_double_image",
    "double_image",
    "double_image_level",
    "local_novelty",
    "evaluate",
    "frame_coverage",
    "frame_step_ratio",
    "grid_labels",
    "index_coverage",
    "lattice_correlation",
    "lattice_lags",
    "lattice_prominence",
    "local_out_of_gamut_share",
    "out_of_gamut_share",
    "patch_coherence",
    "patch_completeness",
    "patch_distances",
    "repetition_lag",
    "repetition_profile",
    "seam_visibility",
    "source_gamut_share",
    "source_local_gamut_share",
    "spectrum_distance",
    "st_power_spectrum",
    "stability",
    "temporal_discontinuity",
]
