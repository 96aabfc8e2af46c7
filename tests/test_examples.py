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
    assert summary["fps"] > 0 and isinstance(summary["over_budget"], int), summary
    assert " fps" in r.stderr, r.stderr  # the rate it reaches, printed as it runs
    assert summary["mean_work_ms"] < summary["budget_ms"], summary  # kept its frame budget on average
    assert summary["window_std"] > 5, summary  # the window shows a texture, not a fill
    assert (summary["speed"], summary["intensity"], summary["scroll"]) == (-1.25, 1.25, 90.0)  # keys reached it


def test_game_loop_reports_its_frame_rate_and_warns_once_over_budget(lds_db):
    pytest.importorskip("pygame", reason="pygame (the examples extra) is not installed: the example needs it")
    import importlib.util
    import io

    spec = importlib.util.spec_from_file_location("game_loop", EXAMPLE)
    game_loop = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(game_loop)
    out = io.StringIO()
    meter = game_loop.RateMeter(budget=0.010, every=0.0, out=out)
    for work in (0.004, 0.020, 0.030, 0.005, 0.011):
        meter.frame(work)
    lines = out.getvalue().splitlines()
    assert meter.over == 3
    assert sum("warning" in line for line in lines) == 1, lines  # said once, at the first overrun
    assert "frame 2 took 20.0 ms, over the 10.0 ms budget" in lines[1]
    assert sum(line.endswith(" fps") for line in lines) == 5, lines  # every=0: a rate after each frame
    assert meter.fps() > 0


def test_game_loop_without_pygame_names_the_extra(tmp_path):
    blocker = tmp_path / "pygame.py"
    blocker.write_text("raise ModuleNotFoundError('No module named pygame', name='pygame')\n")
    env = dict(os.environ, PYTHONPATH=str(tmp_path))
    r = subprocess.run([sys.executable, str(EXAMPLE), "--frames", "1"], capture_output=True, text=True, env=env)
    assert r.returncode == 1 and 'pip install -e ".[examples]"' in r.stderr, r.stderr
