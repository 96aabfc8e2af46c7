"""Lattice prominence (a cell lattice standing out in the output's autocorrelation) and the
stability measure's calibration to a clip's own window-to-window energy."""

from __future__ import annotations

import numpy as np
import pytest

from dynatex.analyzer import load_clip
from dynatex.analyzer import metrics as m

from .test_metrics_calibration import lds_clip


def _smooth_noise(t: int, h: int, w: int, sigma: float, seed: int = 0) -> np.ndarray:
    import cv2

    rng = np.random.default_rng(seed)
    n = rng.normal(0, 1, (t, h, w)).astype(np.float32)
    n = np.stack([cv2.GaussianBlur(f, (0, 0), sigma) for f in n])
    g = np.clip(128 + 40 * n / n.std(), 0, 255).astype(np.uint8)
    return np.repeat(g[..., None], 3, axis=3)


def test_wallpaper_of_one_tile_scores_high():
    tile = _smooth_noise(4, 40, 48, 2.0, seed=1)
    wallpaper = np.tile(tile, (1, 6, 7, 1))
    prom, lags = m.lattice_prominence(wallpaper, (40, 48), per_lag=True)
    assert prom > 0.9, prom
    assert set(lags) == {f"({dy}, {dx})" for dy, dx in m.lattice_lags((40, 48))}
    assert min(lags.values()) > 0.9


def test_random_fields_score_about_zero():
    white = np.random.default_rng(2).integers(0, 256, (4, 240, 320, 3)).astype(np.uint8)
    smooth = _smooth_noise(4, 240, 320, 5.0, seed=3)
    for clip in (white, smooth):
        assert abs(m.lattice_prominence(clip, (40, 48))) < 0.02


def test_a_smooth_correlation_is_not_a_lattice():
    """Large blobs correlate strongly at short lags; the ring around each lag takes that
    decay out, so only a peak at the lag itself counts."""
    blobs = _smooth_noise(3, 240, 320, 12.0, seed=4)
    assert m.lattice_correlation(blobs, 16)[1] > 0.3  # the plain correlation is high
    assert abs(m.lattice_prominence(blobs, 16)) < 0.03


def test_partial_lattice_scores_in_between():
    """A wallpaper whose cells carry their own noise on top of one shared tile."""
    tile = _smooth_noise(2, 32, 32, 2.0, seed=5).astype(np.float32)
    wall = np.tile(tile, (1, 8, 8, 1))
    noise = _smooth_noise(2, 256, 256, 2.0, seed=6).astype(np.float32)
    mixed = np.clip(0.5 * wall + 0.5 * noise, 0, 255).astype(np.uint8)
    assert 0.2 < m.lattice_prominence(mixed, 32) < 0.8


def test_lags_that_do_not_fit_are_left_out():
    clip = _smooth_noise(2, 60, 80, 2.0)
    assert m.lattice_prominence(clip, (64, 64)) is None
    assert m.lattice_prominence(clip, (64, 64), per_lag=True) == (None, {})
    with pytest.raises(ValueError, match="tile"):
        m.lattice_prominence(clip, (0, 8))


def test_stability_accepts_a_clip_whose_energy_varies_against_itself():
    """Energy that swells and fades (boiling water: windows 0.55..2.12 of the whole) is the
    clip's own behaviour, not a decay or a blow-up."""
    base = _smooth_noise(200, 24, 32, 1.5, seed=7).astype(np.float32) - 128
    amp = 1.0 + 0.75 * np.sin(np.linspace(0, 2 * np.pi, 200))[:, None, None, None]
    clip = np.clip(128 + amp * base, 0, 255).astype(np.uint8)
    rep = m.stability(clip, clip)
    assert rep.source_max_ratio > 2.0 and rep.source_min_ratio < 0.5  # outside the plain band
    assert rep.is_stable()
    lo, hi = rep.bounds()
    assert lo < 0.5 and hi > 2.0
    # the same clip decaying to its mean still fails
    mean = clip.astype(np.float32).mean(axis=0)
    decayed = np.rint(mean + 0.97 ** np.arange(200)[:, None, None, None] * (clip - mean)).astype(np.uint8)
    assert not m.stability(decayed, clip).is_stable()


def test_stability_bounds_still_catch_lds_decay_and_blow_up():
    source, x_last = lds_clip(200, decay=0.95, noise=True, seed=0)
    decayed, _ = lds_clip(400, decay=0.95, noise=False, x0=x_last)
    grows, _ = lds_clip(300, decay=1.02, noise=False, x0=x_last, quantize=False)
    assert m.stability(source, source).is_stable()
    assert not m.stability(decayed, source).is_stable()
    assert not m.stability(grows, source).is_stable()


@pytest.mark.clips
def test_every_real_clip_is_stable_against_itself(clips_dir):
    files = sorted(p for p in clips_dir.rglob("*") if p.suffix.lower() in (".avi", ".mp4", ".mov", ".gif"))
    assert files
    for path in files:
        frames = load_clip(path, **({"size": (180, 320)} if "720p" in path.name else {})).frames
        rep = m.stability(frames, frames)
        assert rep.is_stable(), (path.name, rep.min_ratio, rep.max_ratio)
