"""The colour set at the projection's store: the kernel equals its numpy reference with and
without the detail, and two flashing red lamps stay red, where the projection alone tints
them cyan (lds) or pink (mixture), on both backends."""

from __future__ import annotations

import h5py
import numpy as np
import pyopencl as cl
import pytest

from dynatex.analyzer import load_clip, metrics
from dynatex.analyzer.gamut import learn_gamut
from dynatex.analyzer.lds import learn_lds
from dynatex.analyzer.metrics.gamut import colour_bins
from dynatex.analyzer.mixture import learn_mixture
from dynatex.errors import InvalidArgumentError
from dynatex.player import open_player
from dynatex.player.engines.projection import LocalColours, cell_sub, open_projector, snap_colours, snap_local
from dynatex.player.modes.projected import COLOURS
from dynatex.player.opencl.selftest import random_colour_set, random_local
from dynatex.player.pixels import FORMATS
from dynatex.tiledb import DatabaseWriter
from dynatex.tiledb.gamut import GamutModel, local_bits

from .test_detail import _model, exact_projection

ON, OFF, WALL = (230, 25, 20), (175, 170, 165), (90, 95, 100)


def lamps(t: int = 100, h: int = 24, w: int = 40, seed: int = 0) -> np.ndarray:
    """Two round lamps on a grey wall, red when on, grey glass when off, flashing every 5 and 7
    frames, with sensor noise. A state past "off" (the negative of red on grey) is cyan; a lamp
    half on is a pink the clip never shows."""
    rng = np.random.default_rng(seed)
    f = np.empty((t, h, w, 3), np.float32)
    f[:] = WALL
    yy, xx = np.mgrid[:h, :w]
    for cx, period in ((w // 4, 5), (3 * w // 4, 7)):
        disc = (yy - h // 2) ** 2 + (xx - cx) ** 2 <= 36
        on = (np.arange(t) // period) % 2 == 0
        f[:, disc] = np.where(on[:, None, None], np.float32(ON), np.float32(OFF))
    f += rng.normal(0, 2, f.shape)
    return np.clip(np.rint(f), 0, 255).astype(np.uint8)


def cyan_share(frames: np.ndarray) -> float:
    """Share of pixels whose green and blue both exceed red by 3 colour bins (24 levels)."""
    f = frames[..., :3].astype(np.int16)
    return float(((f[..., 1] > f[..., 0] + 24) & (f[..., 2] > f[..., 0] + 24)).mean())


def red_share(frames: np.ndarray) -> float:
    f = frames[..., :3].astype(np.int16)
    return float(((f[..., 0] > 180) & (f[..., 1] < 80) & (f[..., 2] < 80)).mean())


def test_snap_clamps_into_the_nearest_bin():
    nearest = np.arange(32**3, dtype=np.uint16)
    cyan = (1 * 32 + 25) * 32 + 25
    grey = (21 * 32 + 21) * 32 + 20
    nearest[cyan] = grey
    px = np.array([[[13, 201, 207], [13, 205, 99]]], np.uint8)
    snap_colours(px, nearest)
    assert px.tolist() == [[[168, 175, 167], [13, 205, 99]]]  # the other pixel's bin is its own


def _kernel_and_references(cl_context, rng, basis, mean, shape, format, detail, frames, gamut, other):
    """Frames ``(got, want, plain)`` of ``frames`` coefficient rows, k per pass: the kernel and its
    reference with colour set ``gamut``, the reference with ``other`` (None: none); and checks
    that the kernel one frame at a time gives the reference's frame."""
    h, w = shape[:2]
    kw = dict(shape=shape, channels=3, format=format, frames=frames, detail=_model(rng, h, w, 3) if detail else None)
    engine = open_projector(basis, mean, ctx=cl_context, queue=cl.CommandQueue(cl_context), gamut=gamut, **kw)
    ref = open_projector(basis, mean, gamut=gamut, **kw)
    bare = open_projector(basis, mean, gamut=other, **kw)
    try:
        coefs = rng.integers(-4, 5, (frames, 5)).astype(np.float32)
        engine.coefs[:] = ref.coefs[:] = bare.coefs[:] = coefs
        lay = [ref.detail.layers(3, k, 1.5) for k in (0, 4, 9, 30)[:frames]] if detail else None
        got, want, plain = (np.empty((frames, *shape), np.uint8) for _ in range(3))
        engine.run(got, count=frames, layers=lay)
        ref.run(want, count=frames, layers=lay)
        bare.run(plain, count=frames, layers=lay)
        single = np.empty(shape, np.uint8)
        engine.coef[:] = coefs[frames // 2]
        engine.run(single, layers=None if lay is None else [lay[frames // 2]])
        np.testing.assert_array_equal(single, want[frames // 2])
        return got, want, plain
    finally:
        engine.close()


@pytest.mark.parametrize("format", ["RGB", "RGBA", "BGRA"])
@pytest.mark.parametrize("detail", [False, True], ids=["alone", "with-detail"])
@pytest.mark.parametrize("size", [(23, 41), (20, 64)], ids=["pixel-by-pixel", "vectors"])
def test_kernel_equals_numpy_reference(cl_context, format, detail, size):
    """With a colour set the projection kernel moves exactly the pixels its reference moves, to
    the same values, k frames per pass and one at a time."""
    rng = np.random.default_rng(7)
    h, w = size
    fmt = FORMATS[format]
    basis, mean = exact_projection(rng, h, w, 3)
    shape = (h, w, fmt.bytes)
    gamut = GamutModel(random_colour_set(rng))
    got, want, plain = _kernel_and_references(cl_context, rng, basis, mean, shape, format, detail, 4, gamut, None)
    np.testing.assert_array_equal(got, want)
    moved = (want != plain).any(axis=-1)
    assert 0.1 < moved.mean() < 0.9  # about half the bins are outside the set
    bins = colour_bins(want[..., list(fmt.rgb)])
    assert (gamut.nearest[bins] == bins).all()


@pytest.mark.parametrize("format", ["RGB", "BGRA"])
@pytest.mark.parametrize("detail", [False, True], ids=["alone", "with-detail"])
@pytest.mark.parametrize("size", [(23, 41), (20, 64)], ids=["pixel-by-pixel", "vectors"])
def test_local_kernel_equals_numpy_reference(cl_context, format, detail, size):
    """With local colour sets (regions of 8 pixels: a work-item's 16 pixels span two, the last
    row and column of regions are narrower) the kernel moves exactly the pixels its reference
    moves, to the same values, k frames per pass and one at a time: the blend of the four
    nearest regions' sets is integers alone. A colour all four hold stays; a corner pixel, whose
    four regions are one, ends in that region's set."""
    rng = np.random.default_rng(11)
    h, w = size
    fmt = FORMATS[format]
    basis, mean = exact_projection(rng, h, w, 3)
    shape = (h, w, fmt.bytes)
    nearest = random_colour_set(rng)
    gamut = GamutModel(nearest, local=random_local(rng, nearest, h, w, 8))
    got, want, raw = _kernel_and_references(cl_context, rng, basis, mean, shape, format, detail, 3, gamut, None)
    np.testing.assert_array_equal(got, want)
    loc = LocalColours(gamut.local, gamut.nearest, h, w)
    bits = local_bits(gamut.local).reshape(-1)
    base = np.stack(loc.regions_and_weights(np.arange(h * w))[0]) << 15
    held = bits[base[:, None] + colour_bins(raw[..., list(fmt.rgb)]).reshape(3, -1).astype(np.int32)].all(0)
    same = (want == raw).all(axis=-1).reshape(3, -1)
    assert held.any() and same[held].all()
    assert 0.5 < (~same).mean()  # about a quarter of the bins in each region's set
    one = (base == base[0]).all(axis=0)  # the frame's outer corners: four regions that are one
    assert one.sum() >= 16
    out_keys = base[0] + colour_bins(want[..., list(fmt.rgb)]).reshape(3, -1).astype(np.int32)
    assert bits[out_keys[:, one]].all()


@pytest.mark.parametrize("size", [(23, 41), (16, 64), (5, 7)])
def test_local_quads_hold_what_all_four_regions_hold(size):
    """The quad of each pixel (the checks that leave a colour alone, or end the blend, with one
    lookup) holds a bin exactly where each of the pixel's four nearest regions does, and any of
    them exactly where one does, at the frame's edges (regions that are one) and inside alike."""
    rng = np.random.default_rng(5)
    h, w = size
    nearest = random_colour_set(rng)
    loc = LocalColours(random_local(rng, nearest, h, w, 8), nearest, h, w)
    assert loc.quads.shape == ((loc.rows + 1) * (loc.cols + 1), 2, 4096)
    bits = local_bits(loc.model).reshape(-1)
    regions = np.stack(loc.regions_and_weights(np.arange(h * w))[0])
    bins = np.flatnonzero(nearest == np.arange(32**3))[::7]
    four = bits[(regions[:, :, None] << 15) + bins].all(axis=0)
    quad = ~loc.quad_lacks[loc.quad_base[:, None] + bins]
    np.testing.assert_array_equal(quad, four)
    one = bits[(regions[:, :, None] << 15) + bins].any(axis=0)
    np.testing.assert_array_equal(loc.quad_any(loc.quad_base[:, None] + bins), one)
    assert (one & ~four).any() == (loc.rows * loc.cols > 1)  # one region alone: the two alike
    assert 0 < four.mean() < 0.6  # each region holds about half the clip's set, a random half of it


def test_the_blend_in_short_runs_is_the_blend_at_once(monkeypatch):
    """numpy blends a frame in runs of pixels (LOCAL_CHUNK): runs that end anywhere in a row give
    the frame's bytes of one run."""
    from dynatex.player.engines import projection

    rng = np.random.default_rng(11)
    h, w = 23, 41
    nearest = random_colour_set(rng)
    loc = LocalColours(random_local(rng, nearest, h, w, 8), nearest, h, w)
    frame = rng.integers(0, 256, (h, w, 3)).astype(np.uint8)
    whole = frame.copy()
    snap_local(whole, loc)
    monkeypatch.setattr(projection, "LOCAL_CHUNK", 37)
    runs = frame.copy()
    snap_local(runs, loc)
    np.testing.assert_array_equal(runs, whole)
    assert (whole != frame).any(axis=-1).mean() > 0.5


def test_local_cell_sets_name_each_regions_bins_and_targets(monkeypatch):
    """The blend's one lookup per region and 16-level cell (:attr:`LocalColours.sets`) names the
    region's target for the cell and whether the region holds each of the cell's 8 bins, for
    every colour of a random set's regions (laid out a few regions at a time)."""
    from dynatex.player.engines import projection

    monkeypatch.setattr(projection, "SETS_AT_ONCE", 4)
    rng = np.random.default_rng(7)
    nearest = random_colour_set(rng)
    loc = LocalColours(random_local(rng, nearest, 20, 30, 8), nearest, 20, 30)
    bits = local_bits(loc.model)
    levels = np.arange(256)
    r, g, b = (a.reshape(-1) for a in np.meshgrid(levels, levels, levels, indexing="ij"))
    pick = rng.choice(len(r), 20000, replace=False)
    r, g, b = r[pick], g[pick], b[pick]
    bins = (r >> 3 << 10) | (g >> 3 << 5) | (b >> 3)
    cells = (r >> 4 << 8) | (g >> 4 << 4) | (b >> 4)
    sets = loc.sets.reshape(-1, 4096)
    assert sets.shape[0] == bits.shape[0] == loc.rows * loc.cols
    for region in range(sets.shape[0]):
        e = sets[region, cells]
        np.testing.assert_array_equal(e & 0x7FFF, loc.model.nearest[region, cells])
        np.testing.assert_array_equal((e >> (16 + cell_sub(r, g, b))) & 1, bits[region, bins])
    assert 0 < bits.mean() < 1


def test_local_sets_blend_across_a_region_border():
    """Red on the left, grey on the right (and below them the clip's colours between the two):
    red projected over the whole frame stays red in the left region's outer half and becomes the
    right's grey (clamped into the grey bin, 144..151 per channel) in the right's, and between the
    two regions' centres it turns from one into the other a little at a time (the clip's set
    alone keeps red everywhere)."""
    src = np.empty((8, 32, 32, 3), np.uint8)
    src[:, :16, :16], src[:, :16, 16:] = (200, 30, 30), (151, 144, 144)
    src[:, 16:] = np.rint(np.linspace((200, 30, 30), (151, 144, 144), 32))
    gamut = learn_gamut(src)
    assert gamut.local.block == 16
    frame = np.full((32, 32, 3), (200, 30, 30), np.uint8)
    basis = np.zeros((1, frame.size), np.float32)
    outs = []
    for model in (gamut, GamutModel(gamut.nearest)):
        p = open_projector(basis, frame.reshape(-1).astype(np.float32), shape=frame.shape, channels=3, gamut=model)
        outs.append(np.empty_like(frame))
        p.run(outs[-1])
    out, clip_only = outs
    assert clip_only.reshape(-1, 3).tolist() == [[200, 30, 30]] * 1024
    assert (out[:8] == out[:1]).all()  # the rows above the upper regions' centres alike
    row = out[0].astype(int)
    assert row[:8].tolist() == [[200, 30, 30]] * 8  # left of the left region's centre (x = 7.5)
    assert row[24:].tolist() == [[151, 144, 144]] * 8  # right of the right one's (x = 23.5)
    steps = np.diff(row, axis=0)
    assert (steps[:, 0] <= 0).all() and (steps[:, 1:] >= 0).all()  # red falls, green and blue rise
    assert np.abs(steps).max() <= 8  # a hard border would step 114 levels of green at once


def _purple_between_red_and_blue(**engine) -> tuple[np.ndarray, GamutModel]:
    src = np.empty((8, 16, 64, 3), np.uint8)
    src[:, :, :32], src[:, :, 32:] = (200, 30, 30), (30, 30, 200)
    gamut = learn_gamut(src)
    frame = np.full((16, 64, 3), (150, 30, 150), np.uint8)
    basis, mean = np.zeros((1, frame.size), np.float32), frame.reshape(-1).astype(np.float32)
    p = open_projector(basis, mean, shape=frame.shape, channels=3, gamut=gamut, **engine)
    try:
        p.run(frame)
    finally:
        p.close()
    return frame, gamut


def test_a_blend_of_two_regions_sets_stays_in_the_clips_set():
    """Red regions beside blue ones: a purple frame blended between their sets would run through
    purples the clip never had; the blend, last, is clamped into the clip's set (red or blue)."""
    out, gamut = _purple_between_red_and_blue()
    bins = colour_bins(out[None]).reshape(out.shape[:2])
    assert (gamut.nearest[bins] == bins).all()
    assert (out[:, :24] == (200, 30, 31)).all() and (out[:, 40:] == (31, 30, 200)).all()
    assert (out == (200, 30, 31)).all(axis=2).sum() == (out == (31, 30, 200)).all(axis=2).sum() == 512


def test_the_kernels_blend_stays_in_the_clips_set(cl_context):
    got, _ = _purple_between_red_and_blue(ctx=cl_context, queue=cl.CommandQueue(cl_context))
    np.testing.assert_array_equal(got, _purple_between_red_and_blue()[0])


@pytest.fixture(scope="module")
def lamps_db(tmp_path_factory):
    src = lamps()
    clip = load_clip(src)
    path = tmp_path_factory.mktemp("lamps") / "lamps.h5"
    with DatabaseWriter(path) as w:
        w.put_texture("lamps", clip.source_info())
        w.put_method("lamps", "lds", learn_lds(clip))
        w.put_method("lamps", "mixture", learn_mixture(clip, components=2, dim=3, pca_dim=12, neighbors=6, pmax=3))
    old = path.with_name("old.h5")
    old.write_bytes(path.read_bytes())
    with h5py.File(old, "a") as f:
        for method in ("lds", "mixture"):
            del f[f"textures/lamps/{method}/gamut"]
    return path, old, src


def _play(path, mode, frames=120, **kw):
    with open_player(path, mode=mode, seed=3, **kw) as p:
        p.intensity = 4.0  # the driving noise pushes states past the clip's: overshoots show
        return np.stack([p.next_frame() for _ in range(frames)])


@pytest.mark.parametrize("mode", ["lds", "mixture"])
def test_flashing_lamps_stay_red(lamps_db, mode):
    path, old, src = lamps_db
    out, before = _play(path, mode, backend="numpy"), _play(old, mode, backend="numpy")
    assert cyan_share(src) == 0.0
    # the projection alone: colours the clip never had (lds: cyan tints past "off")
    assert metrics.out_of_gamut_share(before, src) > 0.01
    if mode == "lds":
        assert cyan_share(before) > 1e-3
    assert cyan_share(out) == 0.0
    assert metrics.out_of_gamut_share(out, src) <= metrics.source_gamut_share(src)
    assert red_share(out) > 0.5 * red_share(src)  # the lamps still light up red


@pytest.mark.parametrize("mode", ["lds", "mixture"])
def test_lamps_on_both_backends(lamps_db, mode, cl_device):
    path, _, src = lamps_db
    a = _play(path, mode, frames=40, backend="opencl", device=cl_device)
    b = _play(path, mode, frames=40, backend="numpy")
    diff = np.abs(a.astype(int) - b)
    assert (diff > 0).mean() <= 1e-3  # the projection's documented tolerance, then the same colour set
    assert cyan_share(a) == 0.0 and metrics.out_of_gamut_share(a, src) == 0.0


@pytest.mark.parametrize("mode", ["lds", "mixture"])
def test_colours_option_chooses_the_sets(lamps_db, mode):
    """'local' holds colours to the regions' sets, 'clip' to the clip's set alone, 'off' leaves the
    projection as it is: the frames of the database without its gamut part."""
    path, old, src = lamps_db
    frames = {c: _play(path, mode, frames=60, backend="numpy", colours=c) for c in COLOURS}
    assert np.array_equal(frames["off"], _play(old, mode, frames=60, backend="numpy"))
    assert metrics.out_of_gamut_share(frames["off"], src) > 0.01
    for c in ("local", "clip"):
        assert cyan_share(frames[c]) == 0.0 and metrics.out_of_gamut_share(frames[c], src) == 0.0
    assert not np.array_equal(frames["local"], frames["clip"])
    assert np.array_equal(frames["local"], _play(path, mode, frames=60, backend="numpy"))  # the default
    with open_player(path, mode=mode, backend="numpy", colours="clip") as p:
        assert p.colours == "clip" and p.engine.local is None and p.engine.nearest is not None
    with pytest.raises(InvalidArgumentError, match="colours"):
        open_player(path, mode=mode, colours="none")


def test_older_database_plays_without_it(lamps_db):
    _, old, _ = lamps_db
    with open_player(old, mode="lds", seed=3, backend="numpy") as p:
        assert p.engine.nearest is None
        assert p.next_frame().shape == (24, 40, 3)
