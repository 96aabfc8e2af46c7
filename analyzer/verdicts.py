"""Verdicts on an :func:`~dynatex.analyzer.metrics.evaluate` report: is each figure in its good range?

Every figure the report holds is judged against the calibrated ranges of ``analyzer/METRICS.md``
(the table "Good ranges and verdicts" there says where each comes from): ``good`` inside the
good range, ``bad`` beyond the bad threshold, ``poor`` between, ``n/a`` where the report has no
value (no ``--boundaries``, frame sizes differ) or the figure has no absolute scale (patch
distances grow with the clip's contrast: they rank outputs of one source, they do not judge
one). ``dynatex evaluate`` prints the verdicts, carries them in its JSON and, with
``--strict``, fails when one is not good; ``--methods auto`` ranks methods by them.

Examples
--------
>>> v = judge({"frame_step_ratio": 0.35, "spectrum_distance_db": 0.4})
>>> [(x["figure"], x["verdict"]) for x in v]
[('frame_step_ratio', 'bad'), ('spectrum_distance_db', 'good')]
>>> worst(v)
'bad'
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

#: verdicts from best to worst (``n/a`` judges nothing)
LEVELS = ("good", "poor", "bad")
NA = "n/a"


@dataclass(frozen=True)
class Band:
    """The good range ``[good_lo, good_hi]`` of a figure and where it turns bad (below ``bad_lo``
    or above ``bad_hi``); between the two it is ``poor``."""

    figure: str
    label: str
    good_lo: float = -math.inf
    good_hi: float = math.inf
    bad_lo: float = -math.inf
    bad_hi: float = math.inf

    def good_text(self) -> str:
        if math.isinf(self.good_lo):
            return f"<= {self.good_hi:g}"
        if math.isinf(self.good_hi):
            return f">= {self.good_lo:g}"
        return f"{self.good_lo:g}..{self.good_hi:g}"

    def judge(self, value: float | None) -> str:
        if value is None:
            return NA
        if math.isnan(value):
            return "bad"
        if self.good_lo <= value <= self.good_hi:
            return "good"
        if value < self.bad_lo or value > self.bad_hi:
            return "bad"
        return "poor"


#: The calibrated bands (analyzer/METRICS.md, "Good ranges and verdicts").
BANDS: dict[str, Band] = {
    b.figure: b
    for b in (
        Band("energy_ratio", "mean energy ratio", 0.8, 1.25, 0.5, 2.0),
        Band("frame_step_ratio", "frame step ratio", 0.8, 1.25, 0.5, 2.0),
        Band("spectrum_distance_db", "spectrum distance (dB)", good_hi=1.0, bad_hi=3.0),
        Band("seam_visibility", "seam visibility mean", good_hi=1.5, bad_hi=2.0),
        Band("temporal_discontinuity", "temporal discontinuity max", good_hi=2.0, bad_hi=3.0),
        Band("frame_coverage", "frame coverage", good_lo=0.5, bad_lo=0.25),
        Band("local_novelty", "local novelty (mixed positions)", good_hi=1.15, bad_hi=1.35),
        Band("repetition_lag", "repetition lag (frames)", good_lo=100, bad_lo=25),
        Band("lattice_prominence", "lattice prominence", good_hi=0.03, bad_hi=0.1),
    )
}


def _value(report: dict[str, Any], figure: str) -> tuple[float | None, bool]:
    """The figure's value in ``report`` and whether the report measured it at all."""
    if figure not in report and figure != "energy_ratio":
        return None, False
    if figure == "energy_ratio":
        st = report.get("stability")
        if st is None:
            return None, "stability" in report
        finite = [r for r in st["ratios"] if r is not None]
        return (sum(finite) / len(finite) if finite else math.nan), True
    v = report[figure]
    if figure == "seam_visibility":
        v = None if v is None else v["mean"]
    elif figure == "temporal_discontinuity":
        v = None if v is None else v["max"]
    elif figure == "lattice_prominence":
        v = None if v is None else v["output"]
    elif figure == "repetition_lag" and v is None:
        v = math.inf  # no repetition found: the best there is
    return (None if v is None else float(v)), True


def judge(report: dict[str, Any]) -> list[dict[str, Any]]:
    """One verdict per figure the report holds: ``{"figure", "label", "value", "good", "verdict"}``.

    The stability figures are judged by their own band (``stability.bounds``: 0.5..2 widened to
    the source's window-to-window range): any window outside, or a non-finite frame, is bad.
    """
    out: list[dict[str, Any]] = []
    st = report.get("stability")
    if st is not None:
        lo, hi = st["bounds"]
        ok = st["stable"]
        out.append(
            {
                "figure": "stability",
                "label": "stability (every window)",
                "value": [st["min_ratio"], st["max_ratio"]],
                "good": f"{lo:.2f}..{hi:.2f} every window, all finite",
                "verdict": "good" if ok else "bad",
            }
        )
    for band in BANDS.values():
        value, present = _value(report, band.figure)
        if not present:
            continue
        verdict = band.judge(value)
        out.append(
            {
                "figure": band.figure,
                "label": band.label,
                "value": None if value is None or math.isinf(value) else value,
                "good": band.good_text(),
                "verdict": verdict,
            }
        )
    return out


def worst(verdicts: list[dict[str, Any]]) -> str:
    """The worst verdict of a list (``n/a`` when none judges anything)."""
    found = [v["verdict"] for v in verdicts if v["verdict"] in LEVELS]
    return max(found, key=LEVELS.index) if found else NA


def score(verdicts: list[dict[str, Any]]) -> float:
    """How far the judged figures are from good, for ranking outputs of one source (0 = all good):
    each poor figure counts 1, each bad one 3."""
    return float(sum({"good": 0, "poor": 1, "bad": 3}.get(v["verdict"], 0) for v in verdicts))


__all__ = ["BANDS", "LEVELS", "NA", "Band", "judge", "score", "worst"]
