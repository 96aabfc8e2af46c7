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
