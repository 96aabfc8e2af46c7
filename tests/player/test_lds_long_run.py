"""20,000 frames from real clips: no NaN, no blow-up, no decay; the state covariance is the learned one."""

from __future__ import annotations

import numpy as np
import pytest

from dynatex.analyzer import load_clip
from dynatex.analyzer.lds import learn_lds
from dynatex.player import open_player
from dynatex.tiledb import DatabaseWriter, open_db

pytestmark = pytest.mark.clips


@pytest.mark.parametrize("clip_name", ["water_sea_waves_dyntex.avi", "fountain_dyntex_6486110.avi"])
def test_twenty_thousand_frames_stay_alive(clips_dir, tmp_path, clip_name):
    clip = load_clip(clips_dir / clip_name)
    path = tmp_path / "t.h5"
    with DatabaseWriter(path) as w:
        w.put_texture("t", clip.source_info())
        w.put_method("t", "lds", learn_lds(clip))
    with open_db(path) as db:
        db.validate()
    with open_player(path, seed=3) as p:
        x = p.advance(20000, record=True)
        assert np.isfinite(x).all()
        cov = np.cov(x[5000:].T, bias=True)
        stationary = p.stationary_cov
        assert abs(np.trace(cov) / np.trace(stationary) - 1) < 0.2
        assert np.linalg.norm(cov - stationary) / np.linalg.norm(stationary) < 0.3
        mean = p.texture.read("lds").mean.reshape(clip.shape)
        source_spread = np.median([np.std(f - mean) for f in clip.frames.astype(np.float32)])
        out = np.empty(p.shape, np.uint8)
        spreads = np.array([np.std(p.render_state(s, out) - mean) for s in x[-5000::50]])
    ratio = spreads / source_spread
    assert ratio.min() >= 0.5 and ratio.max() <= 2.0, (ratio.min(), ratio.max())


def _mean_frequency(sig: np.ndarray, segment: int = 1024) -> float:
    """Power-weighted mean temporal frequency (cycles per frame) of the series ``sig`` (T, P), DC left out."""
    sig = sig - sig.mean(axis=0)
    win = np.hanning(segment)[:, None]
    power = sum(
        np.abs(np.fft.rfft(sig[i : i + segment] * win, axis=0)) ** 2
        for i in range(0, len(sig) - segment + 1, segment // 2)
    ).sum(axis=1)[1:]
    f = np.arange(1, power.size + 1) / segment
    return float((f * power).sum() / power.sum())


def test_speed_scales_time_on_a_real_clip(clips_dir, tmp_path):
    """Speed 2 and 0.5 move the output's mean temporal frequency x2 and x0.5 (within 15%) and keep its
    energy (within 20%) on the sea (``benchmarks/quality_speed.py`` measures three clips at full size)."""
    clip = load_clip(clips_dir / "water_sea_waves_dyntex.avi", size=(72, 88))
    path = tmp_path / "s.h5"
    with DatabaseWriter(path) as w:
        w.put_texture("s", clip.source_info())
        w.put_method("s", "lds", learn_lds(clip, n=30))
    pix = np.random.default_rng(0).choice(clip.frames[0].size, 500, replace=False)
    found = {}
    for speed in (1.0, 2.0, 0.5):
        with open_player(path, seed=2) as p:
            p.advance(50)
            p.speed = speed
            x = p.advance(12000, record=True)
            model = p.texture.read("lds")
            sig = x @ model.basis[:, pix].astype(np.float64)
        found[speed] = (_mean_frequency(sig), float(np.mean(sig**2)))
    for speed in (2.0, 0.5):
        assert abs(found[speed][0] / found[1.0][0] / speed - 1) <= 0.15, found
        assert 0.8 <= found[speed][1] / found[1.0][1] <= 1.25, found
