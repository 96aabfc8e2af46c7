"""The game-loop example runs headless (SDL's dummy video driver) for a few hundred frames."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "game_loop.py"


def test_game_loop_draws_frames_within_its_budget(lds_db):
    pytest.importorskip("pygame", reason="pygame (the test extra) is not installed: the example needs it")
    env = dict(os.environ, SDL_VIDEODRIVER="dummy", SDL_AUDIODRIVER="dummy")
    r = subprocess.run(
        [
            sys.executable,
            str(EXAMPLE),
            str(lds_db),
            "--frames",
            "300",
            "--fps",
            "120",
            "--autopilot",
            "--backend",
            "numpy",
        ],
        capture_output=True,
        text=True,
        env=env,
        check=False,
        timeout=120,
    )
    assert r.returncode == 0, r.stderr
    summary = json.loads(r.stdout.strip().splitlines()[-1])
    assert summary["frames"] == 300
    assert summary["mean_work_ms"] < summary["budget_ms"], summary  # kept its frame budget on average
    assert summary["window_std"] > 5, summary  # the window shows a texture, not a fill
    assert (summary["speed"], summary["intensity"], summary["scroll"]) == (-1.25, 1.25, 90.0)  # keys reached it
