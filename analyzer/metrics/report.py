"""Every metric at once: the report of :func:`evaluate` (``dynatex evaluate``)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from ...checks import check_frames
from ._common import int_pair
from .gamut import out_of_gamut_share, source_gamut_share
from .ghosts import local_novelty
from .lattice import lattice_correlation, lattice_prominence
from .likeness import patch_distances, spectrum_distance
from .longrun import stability
from .memo import remembering
from .repetition import frame_coverage, repetition_lag
from .seams import frame_step_ratio, seam_visibility, temporal_discontinuity


def evaluate(
    output: np.ndarray,
    source: np.ndarray,
    *,
    labels: np.ndarray | None = None,
    wrap: bool = False,
    events: Sequence[int] | None = None,
    window: int = 25,
    downscale: int | None = None,
    seed: int = 0,
    n_samples: int = 1000,
    period: Sequence[int] | None = None,
    lattice: Sequence[int] | None = None,
) -> dict[str, Any]:
    """Every metric of this module for one output against its source, as a JSON-ready dict.

    ``output_size`` and ``source_size`` are ``[height, width]``. Size-bound metrics
    (stability, frame coverage, local novelty) are None when the frame sizes differ;
    when the output holds NaN/inf, only stability is computed. With ``period`` ``(py, px)``
    (a tile lattice) the lattice correlation of the output and of the source (None where
    a frame is not larger than the period) at those lags. With ``lattice`` ``(th, tw)`` (the
    player's cell lattice) the :func:`lattice_prominence` of the output and of the source (None
    where no lag fits the frame), with the output's figure per lag.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> clip = rng.integers(0, 256, (20, 32, 32, 3)).astype(np.uint8)
    >>> rep = evaluate(clip, clip, window=20)
    >>> rep["stability"]["final_ratio"], rep["frame_coverage"], rep["spectrum_distance_db"]
    (1.0, 1.0, 0.0)
    """
    source = check_frames(source, name="source", min_frames=2)
    output = check_frames(output, name="output", min_frames=2, allow_nonfinite=True)
    with remembering(output, source):  # the luma and the source side each metric takes, once
        same = output.shape[1:] == source.shape[1:]
        report: dict[str, Any] = {
            "output_frames": int(output.shape[0]),
            "source_frames": int(source.shape[0]),
            "output_size": [int(output.shape[1]), int(output.shape[2])],  # (height, width)
            "source_size": [int(source.shape[1]), int(source.shape[2])],
        }
        report["stability"] = stability(output, source, window=window).as_dict() if same else None
        if report["stability"] is not None and report["stability"]["nonfinite_frames"]:
            return report
        output = check_frames(output, name="output", min_frames=2)
        if labels is not None or wrap:
            r = seam_visibility(output, labels, wrap=wrap)
            report["seam_visibility"] = {"mean": float(r.mean()), "max": float(r.max())}
        else:
            report["seam_visibility"] = None
        if events:
            r = temporal_discontinuity(output, events, source=source)
            report["temporal_discontinuity"] = {
                "events": [int(e) for e in events],
                "ratios": r.tolist(),
                "max": float(r.max()),
            }
        else:
            report["temporal_discontinuity"] = None
        report["frame_step_ratio"] = frame_step_ratio(output, source)
        report["spectrum_distance_db"] = spectrum_distance(output, source, downscale=downscale)
        coh, comp = patch_distances(output, source, downscale=downscale, seed=seed, n_samples=n_samples)
        report["patch_coherence"] = coh
        report["patch_completeness"] = comp
        report["frame_coverage"] = frame_coverage(output, source) if same else None
        report["local_novelty"] = local_novelty(output, source) if same and source.shape[0] >= 4 else None
        report["repetition_lag"] = repetition_lag(output, source=source)
        report["out_of_gamut_share"] = out_of_gamut_share(output, source)
        report["source_out_of_gamut_share"] = source_gamut_share(source)
        if period is not None:
            py, px = int_pair("period", period, 1)

            def correlation(frames: np.ndarray) -> list[float] | None:
                if frames.shape[1] <= py or frames.shape[2] <= px:
                    return None  # no lag of the period fits inside the frame
                return list(lattice_correlation(frames[:: max(1, len(frames) // 30)], (py, px)))

            report["lattice_correlation"] = {
                "period": [py, px],
                "output": correlation(output),
                "source": correlation(source),
            }
        if lattice is not None:
            th, tw = int_pair("lattice", lattice, 1)
            prom, lags = lattice_prominence(output, (th, tw), per_lag=True)
            report["lattice_prominence"] = {
                "tile": [th, tw],
                "output": prom,
                "lags": lags,
                "source": lattice_prominence(source, (th, tw)),
            }
        return report
