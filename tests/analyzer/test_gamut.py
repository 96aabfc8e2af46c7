"""The out-of-gamut share: zero for a clip against itself, the source's own level from its
halves, tints a clip never had counted; and, on real clips, its calibration on sources."""

from __future__ import annotations

import numpy as np
import pytest

from dynatex.analyzer import metrics as m
from dynatex.analyzer.video import load_clip_path


def _red_lamp(t=20, seed=0):
    """A red lamp flashing on a dark background, with sensor noise."""
    rng = np.random.default_rng(seed)
    f = np.zeros((t, 16, 16, 3), np.float32)
    level = 60 + 180 * (np.arange(t) % 4 < 2)
    f[:, 4:12, 4:12, 0] = level[:, None, None]
    f[:, 4:12, 4:12, 1:] = 0.1 * level[:, None, None, None]
    f += rng.normal(0, 2, f.shape)
    return np.clip(np.rint(f), 0, 255).astype(np.uint8)


def test_clip_against_itself_and_its_halves():
    src = _red_lamp()
    assert m.out_of_gamut_share(src, src) < 0.01
    assert m.source_gamut_share(src) < 0.01


def test_tints_the_clip_never_had_are_counted():
    src = _red_lamp()
    out = src.copy()
    out[:, 4:8, 4:12, 1:] = out[:, 4:8, 4:12, :1]  # the top half of the lamp turns white-ish / cyan tints
    out[:, 4:8, 4:12, 0] //= 3
    share = m.out_of_gamut_share(out, src)
    assert share == pytest.approx(32 / 256, abs=0.02)
    assert share > 10 * m.source_gamut_share(src)


def test_grey_and_float_clips_are_accepted():
    g = np.roll(np.broadcast_to(np.linspace(0, 255, 64).reshape(8, 8), (4, 8, 8)), 1, axis=2)  # float grey
    assert m.out_of_gamut_share(g, g.astype(np.uint8)) == 0.0
    with pytest.raises(ValueError, match="source"):
        m.source_gamut_share(g[:1])


def test_evaluate_reports_both_levels():
    src = _red_lamp(t=24)
    rep = m.evaluate(src, src, window=12, downscale=1, n_samples=50)
    assert rep["out_of_gamut_share"] < 0.01 and rep["source_out_of_gamut_share"] < 0.01


@pytest.mark.parametrize(
    "name", ["water_sea_waves_dyntex.avi", "flag_wind_dyntex_571c110.avi", "small_64px/fire_dyntex_64px.avi"]
)
def test_calibrated_on_real_sources(clips_dir, name):
    """A source's own level (its halves against each other) is small, and a clip shown with its
    channels swapped (colours it never had) lies far above it."""
    src = load_clip_path(str(clips_dir / name), stop=60).frames
    own = m.source_gamut_share(src)
    assert own < 0.02
    swapped = src[..., ::-1]
    assert m.out_of_gamut_share(swapped, src) > max(0.05, 5 * own)


def _two_halves(t=20, seed=0):
    """Red on the left half of the frame, grey on the right, with sensor noise."""
    rng = np.random.default_rng(seed)
    f = np.empty((t, 32, 32, 3), np.float32)
    f[:, :, :16] = (200, 30, 30)
    f[:, :, 16:] = (150, 150, 145)
    f += rng.normal(0, 2, f.shape)
    return np.clip(np.rint(f), 0, 255).astype(np.uint8)


def test_local_share_counts_a_clip_colour_out_of_its_place():
    src = _two_halves()
    assert m.source_local_gamut_share(src) < 0.01
    assert m.local_out_of_gamut_share(src, src) < 0.01
    moved = src[:, :, ::-1]  # grey on the left, red on the right: colours of the clip, each out of place
    assert m.out_of_gamut_share(moved, src) < 0.01
    assert m.local_out_of_gamut_share(moved, src) > 0.95
    half = src.copy()
    half[:, :16, 16:] = src[:, :16, :16]  # red over the top of the grey half
    assert m.local_out_of_gamut_share(half, src) == pytest.approx(0.25, abs=0.02)
    with pytest.raises(ValueError, match="differ in size"):
        m.local_out_of_gamut_share(src[:, :16], src)


@pytest.mark.parametrize("name", ["flag_wind_dyntex_571c110.avi", "fountain_dyntex_6486110.avi"])
def test_local_share_calibrated_on_real_sources(clips_dir, name):
    """A source's own local level (its halves against each other) is small, and its frames
    mirrored left to right (its colours, in other places) lie far above it."""
    src = load_clip_path(str(clips_dir / name), stop=60).frames
    own = m.source_local_gamut_share(src)
    assert own < 0.02
    assert m.local_out_of_gamut_share(src[:, :, ::-1], src) > max(0.02, 3 * own)


def test_a_large_clip_leaves_its_rarest_colours_out_of_the_set(monkeypatch):
    """A bin held by a few pixels of a clip of many is noise at the set's edge, where the player
    moves colours the clip never had: the set takes MIN_SHARE of the clip's pixels where that is
    more than MIN_PIXELS (here a share made large, so that a small clip shows it)."""
    from dynatex.analyzer import gamut

    clip = np.zeros((10, 20, 20, 3), np.uint8)
    clip[..., 0] = 200
    clip[0, 0, :6] = (0, 0, 200)  # blue: 6 of the clip's 4,000 pixels
    blue = (0 * 32 + 0) * 32 + 25
    assert gamut.learn_gamut(clip).nearest[blue] == blue  # 6 >= MIN_PIXELS
    monkeypatch.setattr(gamut, "MIN_SHARE", 0.002)  # 8 pixels of 4,000
    model = gamut.learn_gamut(clip)
    assert model.info["min_pixels"] == 8 and model.nearest[blue] != blue
    assert gamut.learn_gamut(clip, min_pixels=4).nearest[blue] == blue  # an explicit count wins
