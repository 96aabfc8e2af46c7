"""Where the benchmarks find the real clips: ``../shared/data/clips`` beside the checkout.

A benchmark run as a script (``python benchmarks/NAME.py``) imports this module as ``_clips``;
each benchmark falls back to a generated clip, or skips a clip, where the folder is absent.
"""

from __future__ import annotations

from pathlib import Path

#: The clips folder (its README lists the clips and their sources).
CLIPS = Path(__file__).resolve().parents[2] / "shared" / "data" / "clips"
#: The real 352x288 DynTex sea-waves clip, the default source of several benchmarks.
SEA = CLIPS / "water_sea_waves_dyntex.avi"
