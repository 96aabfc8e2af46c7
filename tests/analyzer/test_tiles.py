"""Tile analysis: period, loop, per-pixel transition, toroidal cuts, compatible tiles, mixing.

Quality figures use analyzer/metrics/ (seam_visibility, temporal_discontinuity).
"""

from __future__ import annotations

import numpy as np
import pytest

from dynatex.analyzer import load_clip, metrics
from dynatex.analyzer.tiles import (
    circular_cut,
    corner_cut,
    find_loop,
    learn_tiles,
    looped_block,
    quilt_geometry,
    ring_join,
    side_join,
    tile_period,
    transition_map,
    wang_edges,
)
from dynatex.analyzer.tiles.quilted import QUILT_SMALL_SIDE, _block_alpha, _blur_matrix, _low_pass, _smoother
from dynatex.analyzer.tiles.stats import feature_scale

from ..conftest import wave_clip


def _stochastic(t=70, h=56, w=72, seed=0):
    """Moving smooth noise: a clip where uncut blocks show seams."""
    import cv2

    rng = np.random.default_rng(seed)
    big = cv2.GaussianBlur(rng.normal(0, 1, (h + t * 2, w + t)).astype(np.float32), (0, 0), 2.5)
    frames = np.stack([big[2 * i : 2 * i + h, i : i + w] for i in range(t)])
    g = np.clip(128 + 60 * frames / frames.std(), 0, 255).astype(np.uint8)
    return np.stack([g, 255 - g, np.clip(g * 0.5 + 60, 0, 255).astype(np.uint8)], axis=3)


@pytest.fixture(scope="module")
def model():
    return learn_tiles(_stochastic(), tile=24, n_tiles=4, min_loop=24)


def test_tile_period_finds_a_stripe_period():
    x = np.arange(160)
    img = (128 + 90 * np.sin(2 * np.pi * x / 20))[None, :].repeat(120, 0)
    f = np.repeat(img[:, :, None], 3, axis=2).astype(np.uint8)[None].repeat(3, 0)
    (th, tw), (py, px), strength = tile_period(f, min_tile=32, max_tile=100)
    assert round(px) == 20 and tw == 40 and strength > 30


def test_tile_period_without_a_period_uses_the_default_size():
    f = np.random.default_rng(0).integers(0, 256, (3, 96, 128, 3), dtype=np.uint8)
    (th, tw), _, strength = tile_period(f, min_tile=16, max_tile=64)
    assert strength < 30 and th == tw == 24


def test_find_loop_recovers_a_periodic_clip():
    base = wave_clip(t=40, h=16, w=20, periods=(40.0, 20.0), seed=1)
    clip = np.concatenate([base, base, base[:20]])
    start, length, cost = find_loop(clip, min_loop=30, transition=4)
    assert length % 40 == 0 and cost < 0.3


def test_transition_map_and_seamless_loop_wrap():
    clip = _stochastic(t=60)
    start, length, _ = find_loop(clip, min_loop=24, transition=6)
    tau = transition_map(clip, start, length, 6)
    assert tau.shape == clip.shape[1:3] and tau.min() >= 0 and tau.max() < 6
    loop = looped_block(clip, start, length, tau, 0, 0, *clip.shape[1:3])
    # where tau > 0 the wrap continues the source: frame 0 is the source frame after frame L-1
    on = tau > 0
    assert (loop[0][on] == clip[start + length][on]).all() and (loop[-1] == clip[start + length - 1]).all()
    twice = np.concatenate([loop, loop])
    assert metrics.temporal_discontinuity(twice, [length], source=clip)[0] <= 1.3


def test_circular_cut_closes():
    rng = np.random.default_rng(0)
    err = rng.random((30, 8))
    path, cost = circular_cut(err, np.ones(30, int))
    assert abs(int(path[0]) - int(path[-1])) <= 1 and (np.abs(np.diff(path)) <= 1).all()
    assert cost <= err.min(axis=1).mean() + err.max()


def test_toroidal_tile_wraps_seamlessly(model):
    tile = model.tiles[0]
    # tile the plane 3x3 with the primary and measure the seam across the wrap
    plane = np.tile(tile, (1, 3, 3, 1))
    th, tw = model.tile_size
    seam = metrics.seam_visibility(plane, metrics.grid_labels(plane.shape[1:3], (th, tw))).mean()
    assert seam <= 1.15, seam


def test_tiles_are_mutually_compatible_and_share_the_ring(model):
    assert model.n_tiles == 4 and (model.tile_class == 0).all()
    th, tw = model.tile_size
    edge = np.zeros((th, tw), bool)
    edge[0], edge[-1], edge[:, 0], edge[:, -1] = True, True, True, True
    for k in range(1, 4):
        assert (model.masks[k][edge] == 255).all()  # the outermost ring is the primary's
        assert (model.tiles[k][:, edge] == model.tiles[0][:, edge]).all()
        assert (model.masks[k] == 0).any()  # and the interior is not
    # a random arrangement of the four is as seamless as the primary with itself
    rng = np.random.default_rng(0)
    pick = rng.integers(0, 4, (4, 5))
    plane = np.concatenate([np.concatenate([model.tiles[k] for k in row], axis=2) for row in pick], axis=1)
    labels = metrics.grid_labels(plane.shape[1:3], (th, tw))
    assert metrics.seam_visibility(plane, labels).mean() <= 1.15


def test_uncut_blocks_are_clearly_worse():
    clip = _stochastic()
    m = learn_tiles(clip, tile=24, n_tiles=2, min_loop=24)
    th, tw = m.tile_size
    rng = np.random.default_rng(1)
    blocks = []
    for _ in range(12):
        y, x, s = rng.integers(0, clip.shape[1] - th), rng.integers(0, clip.shape[2] - tw), rng.integers(0, 30)
        blocks.append(clip[s : s + 30, y : y + th, x : x + tw])
    plane = np.concatenate([np.concatenate(blocks[r * 4 : (r + 1) * 4], axis=2) for r in range(3)], axis=1)
    labels = metrics.grid_labels(plane.shape[1:3], (th, tw))
    uncut = metrics.seam_visibility(plane, labels).mean()
    tiled = np.tile(m.tiles[0][:30], (1, 3, 4, 1))
    cut = metrics.seam_visibility(tiled, labels).mean()
    assert uncut > 2 * cut and uncut > 1.5


def test_ring_join_and_side_join_masks():
    rng = np.random.default_rng(0)
    a = rng.integers(0, 256, (4, 20, 24, 3), dtype=np.uint8)
    b = rng.integers(0, 256, (4, 20, 24, 3), dtype=np.uint8)
    tile, weight, cost = ring_join(a, b, 4)
    assert cost > 0 and (weight[[0, -1]] == 255).all() and (weight[:, [0, -1]] == 255).all()
    assert (weight[6:-6, 6:-6] == 0).all()
    assert (tile[:, weight == 255] == a[:, weight == 255]).all() and (tile[:, weight == 0] == b[:, weight == 0]).all()
    # the cut is smoothed and cross-faded: no step of more than half the range between neighbours
    assert np.abs(np.diff(weight.astype(int), axis=0)).max() < 200 and np.abs(np.diff(weight.astype(int))).max() < 200
    for side in ("left", "right", "top", "bottom"):
        tile, weight, _ = side_join(a, b, 4, side, feather=3)
        line = {"left": weight[:, 0], "right": weight[:, -1], "top": weight[0], "bottom": weight[-1]}[side]
        opposite = {"left": weight[:, -1], "right": weight[:, 0], "top": weight[-1], "bottom": weight[0]}[side]
        assert (line == 255).all() and (opposite == 0).all()
    with pytest.raises(ValueError, match="side"):
        side_join(a, b, 4, "middle")


def test_mixing_builds_border_tiles_and_colour_stats():
    main = _stochastic(seed=0)
    other = np.ascontiguousarray(_stochastic(seed=5)[..., ::-1])
    m = learn_tiles(main, tile=24, n_tiles=2, min_loop=24, mix=[other], names=["a", "b"])
    assert m.class_names == ["a", "b"]
    assert len(m.tiles_of(0)) == 2 and len(m.tiles_of(1)) == 2
    border = m.ring_class != m.tile_class
    assert border.sum() == 8 and sorted(m.border_side[border].tolist()) == [0, 0, 1, 1, 2, 2, 3, 3]
    assert m.loop_length == m.tiles.shape[1]
    assert np.allclose(m.mean_rgb[0], m.tiles[0].reshape(-1, 3).mean(axis=0), atol=3)
    assert (m.mean_hsv[:, 0] >= 0).all() and (m.mean_hsv[:, 0] < 360).all() and (m.mean_hsv[:, 1:] <= 1).all()


def test_progress_reaches_its_total():
    calls = []
    learn_tiles(_stochastic(t=50), tile=16, n_tiles=2, min_loop=20, progress=lambda d, t: calls.append((d, t)))
    assert calls and calls[-1][0] == calls[-1][1] and all(d <= t for d, t in calls)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"tile": 80}, "larger than the clip frame"),
        ({"tile": "big"}, "tile must be an integer"),
        ({"min_loop": 90}, "fewer than the shortest loop"),
        ({"n_tiles": 0}, "n_tiles"),
        ({"transition": 30, "min_loop": 20}, "transition"),
        ({"flow_gain": -1}, "flow_gain"),
        ({"ring": 20, "tile": 24}, "ring"),
        ({"names": ["only", "two"]}, "names"),
    ],
)
def test_bad_input_is_a_clear_error(kwargs, message):
    with pytest.raises(ValueError, match=message):
        learn_tiles(_stochastic(t=50), **kwargs)


def test_mix_clip_shorter_than_the_loop_is_a_clear_error():
    with pytest.raises(ValueError, match="fewer than the loop length"):
        learn_tiles(_stochastic(t=60), tile=16, min_loop=40, mix=[_stochastic(t=30, seed=2)])


def test_grey_clip_is_expanded():
    m = learn_tiles(_stochastic(t=50)[..., :1], tile=16, n_tiles=1, min_loop=20)
    assert m.tiles.shape[-1] == 3 and (m.tiles[..., 0] == m.tiles[..., 1]).all()


@pytest.mark.clips
def test_real_clip_tiles_are_seamless(clips_dir):
    clip = load_clip(str(clips_dir / "grass_straw_wind_dyntex.avi"), stop=120, size=(144, 176))
    m = learn_tiles(clip, n_tiles=2, min_loop=40)
    th, tw = m.tile_size
    plane = np.tile(m.tiles[0][:40], (1, 2, 2, 1))
    seam = metrics.seam_visibility(plane, metrics.grid_labels(plane.shape[1:3], (th, tw))).mean()
    twice = np.concatenate([m.tiles[0], m.tiles[0]])
    wrap = metrics.temporal_discontinuity(twice, [m.loop_length], source=clip.frames)[0]
    assert seam <= 1.15 and wrap <= 1.3, (seam, wrap)


# -- Wang construction -------------------------------------------------------------------------
def test_wang_edges_hold_one_tile_per_left_top_bottom():
    for k in (2, 3):
        e = wang_edges(k).astype(int)
        assert e.shape == (k**3, 4) and e.min() == 0 and e.max() == k - 1
        assert len({(a, c, d) for a, _, c, d in e}) == k**3
        assert ((e[:, 0] + e[:, 2] + e[:, 3]) % k == e[:, 1]).all()


def test_corner_cut_keeps_each_strip_on_its_own_edge():
    rng = np.random.default_rng(2)
    for d, band in ((6, 2), (9, 3), (11, 1)):
        hs, vs = rng.random((4, d, d, 3)), rng.random((4, d, d, 3))
        take_h = corner_cut(hs, vs, band)
        assert take_h[0].all()  # the horizontal edge: its strip
        assert take_h[band + 1 :, 0].sum() == 0  # the vertical edge past the band: the other
        first = np.argmax(take_h, axis=1)
        assert (np.diff(first) >= 0).all() and (np.abs(first - np.arange(d)) <= band).all()
    # a zero-cost staircase is the path taken
    hs, vs = np.ones((1, 6, 6, 3)), np.zeros((1, 6, 6, 3))
    for i in range(6):
        hs[0, i, i] = vs[0, i, i] = 0
    assert (np.argmax(corner_cut(hs, vs, 2), axis=1) == np.arange(6)).all()


@pytest.fixture(scope="module")
def wang_model():
    return learn_tiles(_stochastic(), tile=24, construction="wang", min_loop=24)


def test_wang_tiles_join_where_edge_colours_match(wang_model):
    """Across an edge of one colour both tiles show the two halves of one strip: the step
    across it is like a step inside a tile; across edges of different colours it is not."""
    m = wang_model
    assert m.wang and m.n_tiles == 8 and m.info["construction"] == "wang"
    t = m.tiles.astype(np.float32)
    e, d = m.edges, m.info["strip_depth"]
    th, tw = m.tile_size
    inner = ((t[:, :, :, 1:] - t[:, :, :, :-1]) ** 2).mean()
    ratios = {True: [], False: []}
    for a in range(8):
        for b in range(8):
            x = ((t[a, :, d : th - d, -1] - t[b, :, d : th - d, 0]) ** 2).mean() / inner
            y = ((t[a, :, -1, d : tw - d] - t[b, :, 0, d : tw - d]) ** 2).mean() / inner
            ratios[bool(e[a, 1] == e[b, 0])].append(x)
            ratios[bool(e[a, 3] == e[b, 2])].append(y)
    assert max(ratios[True]) < 1.5, max(ratios[True])
    assert np.mean(ratios[False]) > 2 * np.mean(ratios[True])


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"construction": "hex"}, "construction must be one of"),
        ({"construction": "wang", "n_tiles": 3}, "n_tiles applies to construction 'ring' only"),
        ({"construction": "wang", "edge_colours": 5}, "edge_colours must be an integer in"),
        ({"construction": "wang", "mix": [_stochastic(seed=1)]}, "cannot mix textures"),
    ],
)
def test_wang_bad_options_are_clear_errors(kwargs, message):
    with pytest.raises(ValueError, match=message):
        learn_tiles(_stochastic(t=40), tile=16, min_loop=12, transition=4, **kwargs)


@pytest.mark.parametrize("side", [10, 17, 18, 34, 48, 64, 100, 127, 128, 288, 1080])
@pytest.mark.parametrize("scale", [None, 0.0, 1.0, 2.5, 8.0, 15.0, 40.0, 500.0])
def test_quilt_block_stays_within_the_clips_bounds(side, scale):
    """Any feature scale: a valid block of at least 16 pixels (or what the clip allows), at most
    half the side under QUILT_SMALL_SIDE and a third of it (16..128) above, overlapping by a
    quarter to a half."""
    block, step, (ch, cw), (py, px) = quilt_geometry(side, side + 20, scale=scale)
    assert block % 8 == 0 and block + 2 <= side and ch % step == 0 and ch >= 64 and py % ch == 0
    assert block // 4 <= block - step <= block // 2
    assert block >= min(16, (side - 2) // 8 * 8)
    if side < QUILT_SMALL_SIDE:
        assert block <= max(16, side // 2)
    else:
        assert abs(block - min(max(side / 3, 16), 128)) <= 4


def _smooth_noise(sigma: float, side: int = 64, t: int = 40, seed: int = 0) -> np.ndarray:
    """Drifting Gaussian-smoothed noise: features about ``sigma`` pixels across."""
    import cv2

    rng = np.random.default_rng(seed)
    big = rng.normal(0, 1, (side + t, side + t)).astype(np.float32)
    big = cv2.GaussianBlur(big, (0, 0), sigma) if sigma > 0 else big
    g = np.stack([big[i : i + side, i : i + side] for i in range(t)])
    g = np.clip(128 + 50 * g / g.std(), 0, 255).astype(np.uint8)
    return np.repeat(g[..., None], 3, axis=3)


def test_a_fine_and_a_coarse_texture_get_different_blocks():
    """The block and overlap follow the measured feature scale: small blocks with narrow overlaps
    for grain, the largest the clip allows with half overlaps for coarse features."""
    fine, coarse = _smooth_noise(0.0), _smooth_noise(6.0)
    s_fine, s_coarse = feature_scale(fine), feature_scale(coarse)
    assert s_fine <= 2.0 and s_coarse >= 8.0
    geo_fine, geo_coarse = quilt_geometry(64, 64, scale=s_fine), quilt_geometry(64, 64, scale=s_coarse)
    assert geo_fine[:2] == (16, 12) and geo_coarse[:2] == (32, 16)
    for frames, (block, step, _, _) in ((fine, geo_fine), (coarse, geo_coarse)):
        m = learn_tiles(frames, construction="quilted", min_loop=16, max_loop=16)
        assert (m.info["quilt_block"], m.info["quilt_step"]) == (block, step)


def test_feature_scale_follows_the_correlation_length_and_its_longest_direction():
    x = np.arange(96)
    streaks = 128 + 100 * np.sin(2 * np.pi * x / 96)[None, None, :] * np.ones((3, 96, 1))  # along y
    scale = feature_scale(np.repeat(streaks.astype(np.uint8)[..., None], 3, axis=3))
    assert scale == 48.0  # the lag limit: correlated all along the streaks
    assert feature_scale(np.full((3, 32, 32, 3), 7, np.uint8)) == 0.0  # flat: no features


def test_quilt_cut_shares_are_continuous_across_the_band():
    """The sharp share steps at the cut; the wide one rises from 0 at the old edge to 1 at the new
    edge, without a jump anywhere (a jump would be a straight edge in the low band)."""
    err = np.random.default_rng(0).random((32, 16))
    for side in ("left", "right", "top", "bottom"):
        sharp, wide = _block_alpha(err if side in ("left", "right") else err.T, side, 3, 5.0)
        w = wide if side in ("left", "right") else wide.T
        s = sharp if side in ("left", "right") else sharp.T
        if side in ("right", "bottom"):
            w, s = w[:, ::-1], s[:, ::-1]
        assert w[:, 0].max() < 0.02 and w[:, 15].min() > 0.98 and (w[:, 16:] == 1).all()
        assert np.abs(np.diff(w, axis=1)).max() <= 0.75 / 3 + 1e-9 and (np.diff(w, axis=1) >= -1e-9).all()
        assert (s[:, :3] == 0).all() and (s[:, 13:] == 1).all()


def test_low_pass_ignores_the_unfilled_torus():
    """The coarse band is smoothed over filled pixels only, by a wide or a narrow Gaussian."""
    assert np.allclose(_blur_matrix(16, 4.0).sum(axis=1), 1.0)
    for sigma in (1.5, 4.0, 12.0):
        up, down = _smoother(16, sigma)
        assert np.allclose((up @ down).sum(axis=1), 1.0, atol=1e-5)
        x = np.full((2, 16, 16, 3), 200.0, np.float32)
        weight = np.zeros((16, 16), np.float32)
        weight[:, :6] = 1.0
        x[:, :, 6:] = 0.0  # what the torus holds where nothing is placed yet
        assert np.allclose(_low_pass(x, (up, down), weight)[:, :, :8], 200.0, atol=1e-2)  # the band and past it
    for n, sigma in ((32, 8.0), (96, 10.0), (96, 30.0)):  # pooled, it stays close to the Gaussian
        up, down = _smoother(n, sigma)
        exact = _blur_matrix(n, sigma)
        assert up.shape[1] < n and np.abs(up @ down - exact).max() < 0.3 * exact.max()


@pytest.mark.parametrize("side", [12, 64])
def test_small_clips_learn_a_quilted_torus_with_the_default_block(side):
    frames = wave_clip(t=40, h=side, w=side)
    m = learn_tiles(frames, construction="quilted", min_loop=16)
    block, step, cell, _ = quilt_geometry(side, side)
    assert (m.info["quilt_block"], m.info["quilt_step"]) == (block, step)
    assert m.info["tile_h"] == cell[0] and m.tiles.shape[2:4] == cell
