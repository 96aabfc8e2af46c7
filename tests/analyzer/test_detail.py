"""Learning the detail part: its level, its colour range and its motion follow the residual."""

from __future__ import annotations

import numpy as np
import pytest

from dynatex.analyzer.detail import learn_detail
from dynatex.analyzer.lds import learn_lds


def _drifting_clip(t=64, h=32, w=32, seed=0):
    """A slow wave (what the projection keeps) plus fine noise drifting one pixel right per frame."""
    rng = np.random.default_rng(seed)
    noise = rng.normal(0, 12, (h, w))
    yy, xx = np.mgrid[:h, :w]
    frames = np.empty((t, h, w, 3))
    for k in range(t):
        base = 128 + 50 * np.sin(0.2 * k + 0.3 * xx + 0.1 * yy)
        frames[k] = (base + np.roll(noise, k, axis=1))[..., None] * np.array([1.0, 0.8, 0.6])
    return np.clip(np.rint(frames), 0, 255).astype(np.uint8)


@pytest.fixture(scope="module")
def learned():
    clip = _drifting_clip()
    return clip, learn_lds(clip, n=3)


def test_residual_share_and_colour_range(learned):
    clip, model = learned
    d = model.detail
    assert 0.02 < d.info["residual_energy"] < 0.5
    assert (d.low <= clip.min(axis=0)).all() and (d.high >= clip.max(axis=0)).all()
    assert d.volume.shape == (32, 32, 32, 3) and np.abs(d.volume).max() > 60


def test_volume_keeps_the_colour_axis(learned):
    _, model = learned
    v = model.detail.volume.reshape(-1, 3).astype(float)
    ratio = np.linalg.lstsq(v[:, :1], v[:, 1:], rcond=None)[0][0]
    np.testing.assert_allclose(ratio, [0.8, 0.6], atol=0.08)  # the residual's colours, not grey or random


def test_volume_moves_with_the_residual(learned):
    """The noise drifts right by a pixel a frame: the volume's frame t+1 matches frame t shifted
    by one pixel far better than frame t in place."""
    _, model = learned
    v = model.detail.volume[..., 0].astype(float)

    def corr(a, b):
        a, b = a - a.mean(), b - b.mean()
        return float((a * b).sum() / np.sqrt((a * a).sum() * (b * b).sum()))

    moved = np.mean([corr(v[k + 1], np.roll(v[k], 1, axis=1)) for k in range(len(v) - 1)])
    still = np.mean([corr(v[k + 1], v[k]) for k in range(len(v) - 1)])
    assert moved > 0.6 and moved > still + 0.4


def test_reconstruction_equal_to_the_clip_leaves_no_detail():
    clip = _drifting_clip(t=16, h=8, w=8)
    flat = clip.reshape(16, -1).astype(np.float32)
    d = learn_detail(clip, lambda a, b: flat[a:b])
    assert d.info["residual_energy"] == 0.0
    assert not d.volume.any()


def test_volume_carries_the_residual_energy():
    """Gain times volume holds the whole residual's energy per pixel (other colour axes' included),
    so played frames keep the clip's energy; a residual whose level varies across the frame
    (here: noise on the left half only) is where the levelled estimate fell short."""
    clip = _drifting_clip().astype(np.float64)
    rng = np.random.default_rng(3)
    clip[:, :, :16] += rng.normal(0, 6, clip[:, :, :16].shape)  # uncorrelated colours, left half
    clip = np.clip(np.rint(clip), 0, 255).astype(np.uint8)
    model = learn_lds(clip, n=3)
    d = model.detail
    y = clip.reshape(len(clip), -1).astype(np.float64) - model.mean
    resid = y - model.states.T @ model.basis.astype(np.float64)
    per_pixel = float((resid**2).sum() / (clip.shape[0] * clip.shape[1] * clip.shape[2]))
    carried = float(
        np.mean(d.gain.astype(np.float64) ** 2) * (d.volume.astype(np.float64) ** 2).mean(axis=(0, 1, 2)).sum()
    )
    assert carried == pytest.approx(per_pixel, rel=0.05)  # the levelled estimate: 0.9


def _blob_clip(t, h, w, sigma, seed=0):
    """Random blobs about ``sigma`` pixels across that change at random from frame to frame."""
    from scipy import ndimage

    rng = np.random.default_rng(seed)
    field = ndimage.gaussian_filter(rng.normal(0, 1, (t, h, w)), (0, sigma, sigma), mode="wrap")
    field *= 40 / field.std()
    return np.clip(np.rint(128 + field), 0, 255).astype(np.uint8)[..., None].repeat(3, axis=-1)


@pytest.mark.parametrize(("sigma", "kept"), [(1.0, True), (16.0, False)])
def test_a_coarse_residual_over_a_frame_larger_than_the_volume_gets_no_detail(tmp_path, sigma, kept):
    from dynatex.tiledb import DatabaseWriter, TileDB

    clip = _blob_clip(12, 144, 160, sigma)  # larger than the 128-pixel volume
    model = learn_lds(clip, n=2)
    assert (model.detail is not None) is kept
    if kept:
        assert model.detail.info["coarse_share"] < 0.5 and "detail_coarse_share" not in model.info
        return
    assert model.info["detail_coarse_share"] > 0.5
    path = tmp_path / "coarse.h5"
    with DatabaseWriter(path) as w:
        w.put_texture("b", _source_info(clip))
        w.put_method("b", "lds", model)
    with TileDB(path) as db:
        facts = db.texture("b").read("lds").describe()
    assert facts["detail"] is False and facts["warning"].startswith("no detail part")


def test_a_coarse_residual_keeps_its_detail_where_the_volume_covers_the_frame():
    clip = _blob_clip(12, 64, 64, 16.0)  # the volume is the frame: nothing repeats
    model = learn_lds(clip, n=2)
    assert model.detail is not None and model.detail.info["coarse_share"] > 0.5


def _source_info(frames):
    from dynatex.analyzer import load_clip

    return load_clip(frames).source_info()
