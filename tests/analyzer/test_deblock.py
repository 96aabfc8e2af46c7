"""The codec's block grid: found on block-coded frames and not on smooth or natural ones, smoothed
away before lds and mixture learn, recorded in the model's info, and the frames of a clip without
one left as they are."""

from __future__ import annotations

import numpy as np
import pytest

from dynatex.analyzer import deblock
from dynatex.analyzer.lds import learn_lds
from dynatex.analyzer.mixture import learn_mixture
from dynatex.analyzer.stream import spill_clip
from dynatex.analyzer.tone import learn_tone
from dynatex.analyzer.video import load_clip_path
from dynatex.errors import InvalidArgumentError

from ..conftest import wave_clip

#: The quantiser step of the synthetic block codec (a coarse MPEG-4 quality).
STEP = 24.0


def _dct_matrix(n: int = 8) -> np.ndarray:
    k = np.arange(n)
    d = np.cos(np.pi * (2 * k[None, :] + 1) * k[:, None] / (2 * n)) * np.sqrt(2 / n)
    d[0] /= np.sqrt(2)
    return d


def block_coded(frames: np.ndarray, step: float = STEP) -> np.ndarray:
    """``frames`` through a block codec's transform: each channel's 8 x 8 blocks (from the
    frame's corner) DCT'd, quantised by ``step`` and transformed back, as MPEG-4 intra blocks are."""
    t, h, w, c = frames.shape
    d = _dct_matrix()
    blocks = frames.astype(np.float64).reshape(t, h // 8, 8, w // 8, 8, c).transpose(0, 1, 3, 5, 2, 4)
    coef = np.round(d @ blocks @ d.T / step) * step
    out = (d.T @ coef @ d).transpose(0, 1, 4, 2, 5, 3).reshape(t, h, w, c)
    return np.clip(np.rint(out), 0, 255).astype(np.uint8)


def smooth_clip(t: int = 24, h: int = 64, w: int = 96) -> np.ndarray:
    """Travelling waves with a little noise, no grid."""
    return wave_clip(t, h, w, seed=3, periods=(13.0, 9.0))


def test_a_block_codec_grid_is_found():
    grid = deblock.detect_grid(block_coded(smooth_clip()))
    assert grid.found["luma_x"] and grid.found["luma_y"]
    assert grid.ratios["luma_x"] > 1.3
    assert grid.describe().startswith("luma 8 px x+y")


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_no_grid_is_found_on_smooth_or_noisy_frames(seed):
    rng = np.random.default_rng(seed)
    noisy = rng.integers(0, 256, (16, 64, 64, 3)).astype(np.uint8)
    for frames in (smooth_clip(), noisy):
        grid = deblock.detect_grid(frames)
        assert not grid.any, grid.describe()
        assert grid.describe() == "none"


def test_a_grid_off_the_frames_corner_is_not_the_codecs():
    """A natural texture with a period-8 structure that does not start at the frame's corner (a
    block grid shifted by 3 pixels) is not taken for the codec's."""
    shifted = np.roll(block_coded(smooth_clip()), 3, axis=(1, 2))
    assert not deblock.detect_grid(shifted).found["luma_x"]


def test_smoothing_removes_the_grid_and_keeps_a_real_edge():
    coded = block_coded(smooth_clip())
    grid = deblock.detect_grid(coded)
    out = deblock.deblock(coded, grid)
    after = deblock.detect_grid(np.clip(np.rint(out), 0, 255).astype(np.uint8))
    assert after.ratios["luma_x"] < 1.15 < grid.ratios["luma_x"]
    assert after.ratios["luma_y"] < 1.15 < grid.ratios["luma_y"]
    # a 120-level edge along a block boundary (after column 39) keeps nearly all its step
    edged = coded.copy()
    edged[:, :, 40:] = np.clip(edged[:, :, 40:].astype(int) + 120, 0, 255)
    out = deblock.deblock(edged, grid)
    step = np.abs(out[:, :, 40].astype(float) - out[:, :, 39]).mean()
    assert step > 0.9 * np.abs(edged[:, :, 40].astype(float) - edged[:, :, 39]).mean()


def test_frames_without_a_grid_are_learned_as_they_are():
    frames = smooth_clip()
    grid, info = deblock.choose(frames, "auto")
    assert grid is None and info == {"codec_grid": "none", "deblocked": False}
    values, learned = deblock.learning_values(frames, grid, None)
    assert learned is frames
    np.testing.assert_array_equal(values, frames.reshape(len(frames), -1).astype(np.float32))


def test_smoothing_forced_on_frames_without_a_grid_changes_them_little():
    """With ``on`` the quantile maps of a grid-free clip are near the identity: its boundaries'
    steps are distributed as the inside's already."""
    frames = smooth_clip()
    grid, info = deblock.choose(frames, "on")
    assert info["deblocked"] and grid is not None
    assert info["codec_grid"] == "none"  # what was found, though every plane and axis is smoothed
    change = np.abs(deblock.deblock(frames, grid) - frames)
    assert change.mean() < 0.2
    assert np.quantile(change, 0.99) < 2.0


@pytest.mark.parametrize(
    "shape", [(3, 1, 1, 3), (3, 4, 4, 3), (2, 9, 9, 3), (3, 17, 17, 1), (4, 8, 40, 1), (3, 15, 33, 3)]
)
@pytest.mark.parametrize("mode", ["auto", "on"])
def test_small_short_and_grey_frames_are_learned_from(shape, mode):
    """Frames smaller than two blocks along an axis, short clips and grey ones: nothing to measure
    there, and the values come out whole and finite; a grey clip states no chroma grid."""
    frames = np.random.default_rng(3).integers(0, 256, shape).astype(np.uint8)
    grid, info = deblock.choose(frames, mode)
    values, learned = deblock.learning_values(frames, grid, None)
    assert values.shape == (shape[0], int(np.prod(shape[1:]))) and np.isfinite(values).all()
    assert learned.shape == frames.shape and learned.dtype == np.uint8
    assert "chroma" not in info["codec_grid"] or shape[-1] == 3


def dark_clip(t: int = 40, h: int = 64, w: int = 96) -> np.ndarray:
    """Waves in dark reds: the blue channel at level 0 on nearly half the pixels and a few levels
    above it elsewhere, where the tone map spreads its levels apart."""
    v = smooth_clip(t, h, w)[..., 0].astype(np.float64)
    return np.clip(np.stack([1.2 * v - 60, 0.5 * v - 50, 0.25 * v - 30], axis=-1), 0, 255).astype(np.uint8)


def test_with_a_tone_map_the_grid_is_smoothed_in_tone_values():
    """A codec's one-level steps in a dark channel are steps of many tone units; smoothed in
    levels, held at 0, they stay in the values the model learns, smoothed in tone values they go."""
    coded = block_coded(dark_clip())
    tone, grid = learn_tone(coded), deblock.detect_grid(coded)
    assert grid.found["luma_x"] and grid.found["luma_y"]

    def blue_ratios(values: np.ndarray) -> tuple[float, float]:
        r = deblock.detect_grid(values.reshape(coded.shape)[..., 2:]).ratios
        return r["luma_x"], r["luma_y"]

    learned, rounded = deblock.learning_values(coded, grid, tone)
    in_levels = np.clip(deblock.deblock(coded, grid), 0, 255)
    for ch in range(3):
        in_levels[..., ch] = np.interp(in_levels[..., ch], np.arange(256), tone.forward[ch])
    assert min(blue_ratios(deblock.learning_values(coded, None, tone)[0])) > 4.0
    assert min(blue_ratios(in_levels)) > 3.0
    assert max(blue_ratios(learned)) < 1.15
    # the detail part's reference: the frames smoothed in levels, rounded
    assert np.array_equal(rounded, np.rint(np.clip(deblock.deblock(coded, grid), 0, 255)).astype(np.uint8))


def test_lds_and_mixture_record_the_grid_and_learn_without_it():
    coded = block_coded(smooth_clip(t=40))
    on = learn_lds(coded, n=6)
    off = learn_lds(coded, n=6, deblock="off")
    assert on.info["deblocked"] and on.info["codec_grid"].startswith("luma 8 px")
    assert not off.info["deblocked"] and off.info["codec_grid"] == "not measured"
    # frames drawn from the model's stationary distribution (its components recombined at random)
    # carry the grid learned without smoothing, and not the one learned with it

    def drawn_ratio(model) -> float:
        states = np.random.default_rng(1).multivariate_normal(np.zeros(model.n), model.stationary_cov, 40)
        frames = np.clip(states @ model.basis + model.mean, 0, 255).astype(np.uint8).reshape(coded.shape)
        return deblock.detect_grid(frames).ratios["luma_x"]

    assert drawn_ratio(on) < 1.15 < drawn_ratio(off)
    mix = learn_mixture(coded, components=2, dim=2, pca_dim=6, neighbors=6, pmax=2)
    assert mix.info["deblocked"] and "codec_grid" in mix.describe()


def test_a_streamed_clip_is_learned_as_it_is(tmp_path):
    path = tmp_path / "clip.npy"
    np.save(path, block_coded(smooth_clip(t=12)))
    assert learn_lds(spill_clip(path), n=4).info["deblocked"] is False
    with pytest.raises(InvalidArgumentError, match="deblock='on' needs the clip in memory"):
        learn_lds(spill_clip(path), n=4, deblock="on")


@pytest.mark.parametrize("value", ["yes", 1, None])
def test_a_bad_deblock_is_named(value):
    with pytest.raises((InvalidArgumentError, TypeError), match="deblock"):
        learn_lds(smooth_clip(), n=4, deblock=value)


def test_real_compressed_clips_are_found_and_grid_free_ones_are_not(clips_dir):
    for name in ("water_sea_waves_dyntex.avi", "grass_straw_wind_dyntex.avi"):
        frames = load_clip_path(str(clips_dir / name)).frames
        grid = deblock.detect_grid(frames)
        assert grid.found["luma_x"] and grid.found["chroma_x"], name
        _, learned = deblock.learning_values(frames, grid, None)
        after = deblock.detect_grid(learned)
        # the luma grid's boundary ratio drops to a grid-free clip's level
        assert after.ratios["luma_x"] < 1.12 < grid.ratios["luma_x"], name
    for name in ("steam_vapour_pot_128px.avi", "timevarying_rusting_steel.gif", "small_64px/fire_dyntex_64px.avi"):
        assert not deblock.detect_grid(load_clip_path(str(clips_dir / name)).frames).any, name


def test_tone_values_smoothed_near_a_dark_grid_stay_in_the_maps_range(tmp_path):
    """Dark 8-px blocks at levels 0 and 2 beside dark waves: smoothed in tone values a ramp on the
    level-0 side would fall below the map's first value, and the mean learned from it outside what
    the format accepts; held to the map's range, both models are written and play."""
    from dynatex.analyzer import load_clip
    from dynatex.analyzer.lds import learn_lds
    from dynatex.analyzer.mixture import learn_mixture
    from dynatex.player import open_player
    from dynatex.tiledb import DatabaseWriter

    t, h, w = 40, 64, 96
    rng = np.random.default_rng(0)
    clip = np.clip(1.6 * smooth_clip(t, h, w).astype(float) - 120, 0, 255)
    dark = rng.integers(0, 2, (h // 8, w // 8)).repeat(8, 0).repeat(8, 1)[None] * 2
    clip[:, :, : w // 2, :] = dark[:, :, : w // 2, None]
    clip = np.rint(np.clip(clip + rng.normal(0, 0.3, clip.shape), 0, 255)).astype(np.uint8)
    models = {
        "lds": learn_lds(clip, n=6, tone="on", deblock="on"),
        "mixture": learn_mixture(clip, components=2, dim=2, pca_dim=6, neighbors=5, pmax=2, tone="on", deblock="on"),
    }
    path = tmp_path / "dark.h5"
    with DatabaseWriter(path) as writer:
        writer.put_texture("dark", load_clip(clip).source_info())
        for method, model in models.items():
            forward = model.tone.forward
            assert forward.min() - 1 <= model.mean.min() and model.mean.max() <= forward.max() + 1
            writer.put_method("dark", method, model)
    for method in models:
        with open_player(path, mode=method, backend="numpy") as player:
            assert player.next_frame().shape == (h, w, 3)
