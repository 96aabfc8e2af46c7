"""Verdicts on evaluate reports: bands, the worst verdict, the ranking score; calibration on real clips."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dynatex.analyzer.verdicts import BANDS, Band, judge, score, worst


def test_band_levels():
    b = Band("x", "x", 0.8, 1.25, 0.5, 2.0)
    assert [b.judge(v) for v in (1.0, 0.8, 1.25, 0.6, 1.5, 0.4, 2.5)] == [
        "good",
        "good",
        "good",
        "poor",
        "poor",
        "bad",
        "bad",
    ]
    assert b.judge(None) == "n/a" and b.judge(math.nan) == "bad"
    assert Band("y", "y", good_hi=1, bad_hi=3).good_text() == "<= 1"


def test_judge_reads_nested_figures_and_missing_ones():
    report = {
        "stability": {"ratios": [0.4, 0.6], "bounds": [0.5, 2.0], "stable": False, "min_ratio": 0.4, "max_ratio": 0.6},
        "seam_visibility": {"mean": 1.7, "max": 3.0},
        "temporal_discontinuity": None,
        "repetition_lag": None,
        "frame_coverage": None,
    }
    v = {x["figure"]: x for x in judge(report)}
    assert v["stability"]["verdict"] == "bad"
    assert v["energy_ratio"]["value"] == pytest.approx(0.5) and v["energy_ratio"]["verdict"] == "poor"
    assert v["seam_visibility"]["verdict"] == "poor"
    assert v["temporal_discontinuity"]["verdict"] == "n/a" and v["frame_coverage"]["verdict"] == "n/a"
    assert v["repetition_lag"]["verdict"] == "good" and v["repetition_lag"]["value"] is None
    assert "spectrum_distance_db" not in v  # not in the report: not judged
    assert worst(list(v.values())) == "bad" and score(list(v.values())) == 3 + 1 + 1
    assert worst([]) == "n/a"


def test_local_novelty_band():
    v = {x["figure"]: x for x in judge({"local_novelty": 1.47})}  # the flag's lds output
    assert v["local_novelty"]["verdict"] == "bad"
    assert [BANDS["local_novelty"].judge(x) for x in (0.0, 1.01, 1.2, None)] == ["good", "good", "poor", "n/a"]


def test_a_ghosted_output_ranks_below_a_clean_one():
    from dynatex.analyzer.auto import _order
    from dynatex.analyzer.metrics import evaluate

    from .test_metrics import _stripes

    src = _stripes(0, t=48)
    ghost = ((src.astype(float) + np.roll(src, 5, axis=2)) / 2).astype(np.uint8)  # stripes at two places
    entries = []
    for name, out in (("ghost", ghost), ("clean", _stripes(1, t=48))):
        report = evaluate(out, src, n_samples=100)
        v = {x["figure"]: x["verdict"] for x in judge(report)}
        entries.append({"mode": name, "score": score(judge(report)), "novelty": v["local_novelty"], **report})
    ghosted, clean = entries
    assert ghosted["novelty"] == "bad" and clean["novelty"] == "good"
    assert [e["mode"] for e in sorted(entries, key=_order)] == ["clean", "ghost"]


def test_every_band_is_ordered():
    for b in BANDS.values():
        assert b.bad_lo <= b.good_lo <= b.good_hi <= b.bad_hi, b.figure


@pytest.mark.clips
@pytest.mark.parametrize("name", ["water_sea_waves_dyntex.avi", "steam_vapour_pot_128px.avi"])
def test_a_clip_against_itself_is_good_everywhere(clips_dir, name):
    from dynatex.analyzer import load_clip
    from dynatex.analyzer.metrics import evaluate

    frames = load_clip(clips_dir / name, stop=120).frames
    v = judge(evaluate(frames, frames, n_samples=200))
    assert worst(v) == "good", [(x["figure"], x["value"]) for x in v if x["verdict"] != "good"]
