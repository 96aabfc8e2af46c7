"""The wrap a closed loop reports (``dynatex play --loop``, ``dynatex export --loop``): the player's
own measure, equal to the metrics' jump at the wrap, without importing the analyzer."""

from __future__ import annotations

import numpy as np
import pytest

from dynatex.analyzer.metrics import temporal_discontinuity
from dynatex.player.loop import wrap_report


@pytest.mark.parametrize("grey", [False, True])
def test_the_wrap_is_the_metrics_jump_at_the_wrap(grey):
    rng = np.random.default_rng(0)
    shape = (6, 8) if grey else (6, 8, 3)
    frames = rng.integers(0, 256, (10, *shape), dtype=np.uint8)
    source = rng.integers(60, 200, (20, *shape), dtype=np.uint8)
    seq = np.concatenate([frames, frames[:1]])
    for ref, name in ((source, "source"), (None, "export"), (source[:1], "export")):
        want = temporal_discontinuity(seq, [len(frames)], source=frames if name == "export" else ref)[0]
        assert wrap_report(frames, ref) == {
            "ratio": round(float(want), 4),
            "reference": f"median frame step of the {name}",
        }


def test_no_wrap_without_two_frames_or_a_moving_reference():
    frames = np.random.default_rng(1).integers(0, 256, (4, 5, 5, 3), dtype=np.uint8)
    assert wrap_report(frames[:1], None) == {"ratio": None, "reference": "one frame: no wrap"}
    still = np.zeros((3, 5, 5, 3), np.uint8)
    report = wrap_report(frames, still)
    assert report["ratio"] is None and report["reference"].startswith("the source does not change")
    assert wrap_report(still, None)["reference"].startswith("the export does not change")
