"""The stochastic layout of a quilted torus (issue 28, item 1): random windows of the torus on a
triangle grid, blended by Heitz and Neyret's histogram-preserving operator; kernel against
its numpy reference, the tables, and what the tiles player draws with it."""

from __future__ import annotations

import numpy as np
import pytest

from dynatex.analyzer import load_clip, metrics
from dynatex.analyzer.tiles import learn_tiles
from dynatex.errors import InvalidArgumentError
from dynatex.player.engines.stochastic import RUN, TRIANGLE_CODES, StochasticOpenCL, cell_pieces
from dynatex.player.engines.stochastic_reference import (
    BAND,
    GS,
    WQ,
    blend_weights,
    gauss_tables,
    inverse_index,
    weight_table,
    window_labels,
)
from dynatex.player.modes.tiles import TilesPlayer, choose_layout, torus_frames
from dynatex.player.opencl import selftest
from dynatex.tiledb import DatabaseWriter

from ..analyzer.test_tiles import _stochastic
from ..conftest import best_backend

PERIOD = (216, 288)


@pytest.fixture(scope="module")
def quilted(tmp_path_factory):
    clip = _stochastic(t=60, h=56, w=72)
    model = learn_tiles(clip, tile=24, min_loop=24, period=PERIOD)
    path = tmp_path_factory.mktemp("stochastic") / "q.h5"
    with DatabaseWriter(path) as w:
        w.put_texture("noise", load_clip(clip).source_info())
        w.put_method("noise", "tiles", model)
    return model, path


@pytest.mark.parametrize(
    "format, cell, band, toned",
    [
        ("RGB", (11, 18), 0.3, True),
        ("RGB", (24, 64), 0.1, False),
        ("RGB", (24, 96), 0.5, True),
        ("RGB", (24, 64), 1.0, False),
        ("RGBA", (24, 96), 0.5, False),
        ("BGRA", (11, 18), 0.1, True),
        ("BGRA", (24, 96), 0.5, True),
    ],
)
def test_kernel_equals_its_reference(cl_device, format, cell, band, toned):
    """Small cells blend almost everywhere, large ones with a narrow band show single windows over
    most pixels, a wide band has whole pieces of both kinds (the kernel's vector stores, in every
    format) and partial ones at the output's edges."""
    rng = np.random.default_rng(4)
    torus = rng.integers(0, 256, (7, 40, 100, 3), dtype=np.uint8)
    s = StochasticOpenCL(torus, (53, 197), device=cl_device, seed=5, cell=cell, band=band, format=format)
    try:
        s.set_time_map(rng.uniform(-40, 40, s.tmap_shape), rng.uniform(0, 9, s.tmap_shape))
        if toned:
            s.set_tones(np.array([[0.7, 1.3, 1.0]]))
        for t, fade in ((0.0, 0.0), (3.6, 0.25), (-11.2, 1.0), (1e5 + 0.4, 0.7)):
            got = s.render(t, fade=fade)
            assert np.array_equal(got, s.render_reference(t, fade=fade)), (t, fade)
    finally:
        s.close()


@pytest.mark.parametrize("cell, band", [((11, 18), 0.3), ((24, 96), 0.5), ((249, 288), BAND)])
def test_pieces_cover_a_cell_once(cell, band):
    """Every pixel of a cell lies in one piece; a copy piece's pixels show its window alone, a blend
    piece's weights are the pixels' own (its windows among the triangle's, zero where one takes no part)."""
    weights = weight_table(cell, band)
    wq = blend_weights(weights)
    pieces, bweights = cell_pieces(weights, RUN)
    seen = np.zeros(cell, int)
    codes = TRIANGLE_CODES[wq[..., 3] & 3]
    for r, c, n, blend, c0, c1, c2, row in pieces:
        assert 1 <= n <= RUN and c + n <= cell[1]
        seen[r, c : c + n] += 1
        single = wq[r, c : c + n, 3] >> 2
        if not blend:
            assert (single > 0).all()
            assert (np.take_along_axis(codes[r, c : c + n], single[:, None] - 1, 1)[:, 0] == c0).all()
            continue
        assert (single == 0).all() and len({c0, c1, c2}) >= 2
        for k in range(n):
            want = dict.fromkeys((c0, c1, c2), 0)
            for code, w in zip(codes[r, c + k], wq[r, c + k, :3]):
                assert w == 0 or code in want
                want[code] = want.get(code, 0) + w
            got = dict(zip(sorted({c0, c1, c2}), bweights[row][:, k]))
            assert all(got[code] == want[code] for code in got)
        assert (bweights[row][:, n:] == 0).all()
    assert (seen == 1).all()


def _pieces_pixel_by_pixel(weights: np.ndarray, run: int) -> tuple[np.ndarray, np.ndarray]:
    """cell_pieces as first written: a walk over every pixel of the cell (the cut it must keep)."""
    wq = blend_weights(weights)
    ch, cw = wq.shape[:2]
    single = wq[..., 3] >> 2
    codes = TRIANGLE_CODES[wq[..., 3] & 3]
    copy_code = np.take_along_axis(codes, np.maximum(single - 1, 0)[..., None], -1)[..., 0]
    pieces, bweights = [], []
    for r in range(ch):
        c = 0
        while c < cw:
            n = 1
            if single[r, c]:
                while n < run and c + n < cw and single[r, c + n] and copy_code[r, c + n] == copy_code[r, c]:
                    n += 1
                pieces.append((r, c, n, 0, copy_code[r, c], 0, 0, 0))
            else:
                taking = {int(v) for v, q in zip(codes[r, c], wq[r, c, :3]) if q > 0}
                while n < run and c + n < cw and not single[r, c + n]:
                    more = taking | {int(v) for v, q in zip(codes[r, c + n], wq[r, c + n, :3]) if q > 0}
                    if len(more) > 3:
                        break
                    taking, n = more, n + 1
                slots = sorted(taking) + [max(taking)] * (3 - len(taking))
                w = np.zeros((3, run), np.int64)
                for k, code in enumerate(sorted(taking)):
                    w[k, :n] = (wq[r, c : c + n, :3] * (codes[r, c : c + n] == code)).sum(-1)
                pieces.append((r, c, n, 1, *slots, len(bweights)))
                bweights.append(w)
            c += n
    return np.array(pieces, np.int32).reshape(-1, 8), np.array(bweights, np.int64).reshape(-1, 3, run)


@pytest.mark.parametrize(
    "cell, band, run",
    [((11, 18), 0.3, RUN), ((24, 96), 0.5, RUN), ((249, 288), BAND, RUN), ((24, 64), 0.5, 16), ((13, 40), 0.2, 16)],
)
def test_pieces_are_the_pixel_walks(cell, band, run):
    """The cut grouped by stretches is the pixel-by-pixel walk's, piece for piece and weight for weight."""
    weights = weight_table(cell, band)
    pieces, bweights = cell_pieces(weights, run)
    want_pieces, want_weights = _pieces_pixel_by_pixel(weights, run)
    assert pieces.dtype == want_pieces.dtype and np.array_equal(pieces, want_pieces)
    assert bweights.dtype == want_weights.dtype and np.array_equal(bweights, want_weights)
    assert pieces[:, 3].any() and not pieces[:, 3].all()


def test_selftest_checks_the_kernel():
    assert {"stochastic tiling, RGB", "stochastic tiling, RGB, toned", "stochastic tiling, BGRA, toned"} <= set(
        selftest.CHECKS
    )


def test_weights_keep_the_variance_and_leave_most_pixels_to_one_window():
    table = weight_table((104, 120))
    single = table[..., 3] >= 4
    w = table[~single][:, :3]
    assert np.allclose((w * w).sum(-1), 1.0, atol=1e-6) and (w >= 0).all()
    assert 0.7 < single.mean() < 0.9  # narrow blend bands along the hexagons' edges, windows alone inside
    assert (table[single][:, :3] == 0).all()
    # a wider band blends more pixels; weights rise from 0 without a step at the band's edge
    assert (weight_table((104, 120), 0.3)[..., 3] >= 4).mean() < 0.6
    assert np.rint(w * WQ).min() <= 1
    with pytest.raises(InvalidArgumentError, match="even width"):
        weight_table((10, 7))
    with pytest.raises(InvalidArgumentError, match="band must be"):
        weight_table((10, 8), 0.0)


def test_gauss_tables_invert_and_keep_the_histogram():
    """The Gaussianized bytes are standard normal at GS levels a deviation; the inverse table gives
    a value back within one (a level holds a few values where the histogram is flat, and in
    its sparse tail several neighbours share one: within 4); a variance-preserving blend of independent draws (the
    kernel's integers) comes back with the source's mean and contrast."""
    rng = np.random.default_rng(2)
    values = np.clip(rng.gamma(2.0, 30.0, (3, 20000)), 0, 255).astype(np.int64)
    hist = np.stack([np.bincount(v, minlength=256) for v in values]).astype(float)
    table, inverse, tone = gauss_tables(hist)
    ch = np.arange(3)[:, None]
    g = (table[ch, values].astype(np.float64) - 128) / GS
    assert abs(g.mean()) < 0.05 and abs(g.std() - 1) < 0.05  # standard normal
    back = inverse[ch, inverse_index(WQ * 255 * (table[ch, values].astype(np.int64) - 128))]
    err = np.abs(back.astype(np.int64) - values)
    assert (err <= 1).mean() > 0.99 and err.max() <= 4
    w = np.rint(np.array([0.6, 0.5, 0.3]) / np.sqrt(0.7) * WQ).astype(np.int64)
    acc = sum(wk * 255 * (table[ch, rng.permutation(values.T).T].astype(np.int64) - 128) for wk in w)
    out = inverse[ch, inverse_index(acc)]
    assert abs(out.mean() - values.mean()) < 2 and abs(out.std() / values.std() - 1) < 0.05
    assert (tone == np.arange(256)).all()
    _, inverse2, tone2 = gauss_tables(hist, np.array([2.0, 1.0, 0.5]))
    assert tone2[0, 100] == 200 and tone2[2, 100] == 50 and inverse2[0].max() == 255


def test_layout_choice():
    assert choose_layout("auto", (500, 800), (576, 720)) == "stochastic"
    assert choose_layout("auto", (576, 720), (576, 720)) == "torus"
    assert choose_layout("torus", (2000, 2000), (576, 720)) == "torus"
    assert choose_layout("auto", (2000, 2000), None) == "torus"
    with pytest.raises(InvalidArgumentError, match="needs a quilted tile set"):
        choose_layout("stochastic", (100, 100), None)
    with pytest.raises(InvalidArgumentError, match="layout must be one of"):
        choose_layout("hex", (100, 100), (64, 64))


def test_a_ring_set_refuses_the_stochastic_layout():
    with pytest.raises(InvalidArgumentError, match="needs a quilted tile set"):
        TilesPlayer(selftest._db_path(), "selftest", size=(200, 200), backend="numpy", layout="stochastic")


def test_torus_frames_put_cells_in_their_order(quilted):
    model, _ = quilted
    torus = torus_frames(model.tiles, model.torus)
    th, tw = model.tile_size
    cols = model.torus[1]
    assert torus.shape[1:3] == PERIOD
    assert np.array_equal(torus[:, th : 2 * th, 2 * tw : 3 * tw], model.tiles[cols + 2])


def _period_correlation(frame: np.ndarray, dy: int, dx: int) -> float:
    g = frame.astype(float).mean(-1)
    a, b = g[: g.shape[0] - dy, : g.shape[1] - dx], g[dy:, dx:]
    return float(np.corrcoef(a.ravel(), b.ravel())[0, 1])


def test_an_output_larger_than_the_torus_has_no_period(quilted):
    _, path = quilted
    size = (2 * PERIOD[0] + 40, 2 * PERIOD[1] + 40)
    backend = best_backend()
    # without time offsets, so that only the layout can break the period
    with TilesPlayer(path, size=size, backend=backend, seed=1, layout="torus") as p:
        p.max_shift = 0.0
        before = p.next_frame()
    with TilesPlayer(path, size=size, backend=backend, seed=1) as p:
        assert p.layout == "stochastic"
        p.max_shift = 0.0
        frames = np.stack([p.next_frame() for _ in range(4)])
        cell = p.engine.cell
    assert _period_correlation(before, 0, PERIOD[1]) > 0.9
    for dy, dx in ((0, PERIOD[1]), (PERIOD[0], 0), PERIOD):
        assert abs(_period_correlation(frames[0], dy, dx)) < 0.25, (dy, dx)
    # not washed out: the output keeps the torus's contrast and mean
    torus = torus_frames(*(lambda m: (m.tiles, m.torus))(quilted[0]))
    assert abs(frames.std() / torus.std() - 1) < 0.08
    assert abs(frames.mean() - torus.mean()) < 4
    # where windows meet, the texture looks like inside them
    assert metrics.seam_visibility(frames, window_labels(size, cell)).mean() < 1.2


def test_backends_agree_and_state_restores(quilted):
    _, path = quilted
    size = (250, 330)
    with TilesPlayer(path, size=size, backend="numpy", seed=6, tone=(120, 110, 100), layout="auto") as ref:
        want = [ref.next_frame() for _ in range(3)]
        state = ref.get_state()
        more = ref.next_frame()
    with TilesPlayer(path, size=size, backend=best_backend(), seed=6, tone=(120, 110, 100), layout="auto") as p:
        assert p.layout == "stochastic"
        for frame in want:
            assert np.array_equal(p.next_frame(), frame)
        p.next_frame()
        p.set_state(state)
        assert np.array_equal(p.next_frame(), more)
    with TilesPlayer(path, size=size, backend="numpy", seed=7, layout="auto") as other:
        assert not np.array_equal(other.next_frame(), want[0])


def test_time_offsets_follow_the_cell_field(quilted):
    _, path = quilted
    with TilesPlayer(path, size=(300, 400), backend="numpy", seed=2, layout="stochastic") as p:
        p.max_shift = 6.0
        offsets = p.engine.time_map
        assert offsets.shape == p.engine.tmap_shape
        assert 0 <= offsets.min() and offsets.max() <= 6.0 and offsets.std() > 0.5
        # an epoch moves on one map: the target becomes the time map (next_time_map)
        p.epoch = 2
        target = p.engine.target_map
        assert not np.array_equal(target, offsets)
        p.next_frame()
        p.next_frame()
        assert np.array_equal(p.engine.time_map, target)
        p.max_shift = 0.0
        assert (p.engine.time_map == 0).all()
