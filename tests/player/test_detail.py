"""The detail: the fused projection kernel equals its numpy reference, the layer schedule keeps the detail's
variance, the colour range holds, and lds/mixture textures play with and without the part."""

from __future__ import annotations

import h5py
import numpy as np
import pyopencl as cl
import pytest

from dynatex.analyzer import load_clip
from dynatex.analyzer.lds import learn_lds
from dynatex.player import open_player
from dynatex.player.engines.detail import DetailReference, layers
from dynatex.player.engines.projection import open_projector
from dynatex.player.pixels import FORMATS
from dynatex.tiledb import DatabaseWriter
from dynatex.tiledb.detail import DetailModel

from ..conftest import wave_clip


def _model(rng, h, w, channels, frames=6, vh=9, vw=14, colours=None):
    low = rng.integers(0, 128, (h, w, channels), dtype=np.uint8)
    return DetailModel(
        volume=rng.integers(-127, 128, (frames, vh, vw, channels), dtype=np.int8),
        gain=rng.uniform(0, 0.6, (h, w)).astype(np.float32),
        low=low,
        high=low + rng.integers(0, 128, (h, w, channels), dtype=np.uint8),
        colours=rng.integers(0, 2, 32**3, dtype=np.uint8) if colours is None else colours,
    )


def exact_projection(rng, h, w, channels, n=5):
    """A basis, mean and coefficients whose sums are exact in float32 in any order: the projected
    integers are the same on every backend, so what follows them (the detail) must be too."""
    basis = rng.integers(-8, 9, (n, h * w * channels)).astype(np.float32)
    mean = rng.integers(-40, 300, h * w * channels).astype(np.float32)
    return basis, mean


@pytest.mark.parametrize("channels", [1, 3])
@pytest.mark.parametrize("format", ["RGB", "RGBA", "BGRA"])
@pytest.mark.parametrize("size", [(23, 41, 9, 14), (20, 64, 24, 40)], ids=["pixel-by-pixel", "vectors"])
def test_fused_kernel_equals_numpy_reference(cl_context, channels, format, size):
    """The projection kernel adds the detail in its own pass, k frames at a time, bit for bit as
    the reference projects and then adds it (rows of whole vectors take the kernel's vector
    path, wrapping in the volume or not, the others its pixel-by-pixel path)."""
    rng = np.random.default_rng(channels)
    h, w, vh, vw = size
    fmt = FORMATS[format]
    model = _model(rng, h, w, channels, vh=vh, vw=vw)
    basis, mean = exact_projection(rng, h, w, channels)
    shape = (h, w, fmt.bytes)
    kw = dict(shape=shape, channels=channels, format=format, frames=5, detail=model)
    queue = cl.CommandQueue(cl_context)
    engine = open_projector(basis, mean, ctx=cl_context, queue=queue, **kw)
    ref = open_projector(basis, mean, **kw)
    try:
        coefs = rng.integers(-4, 5, (5, 5)).astype(np.float32)
        engine.coefs[:] = ref.coefs[:] = coefs
        lay = [ref.detail.layers(9, k, 2.0) for k in (0, 1, 5, 17, 1000)]
        got, want, bare = (np.empty((5, *shape), np.uint8) for _ in range(3))
        engine.run(got, count=5, layers=lay)
        ref.run(want, count=5, layers=lay)
        ref.run(bare, count=5)
        np.testing.assert_array_equal(got, want)
        assert (want != bare).sum() > 0  # the detail did something the comparison could catch
        single = np.empty(shape, np.uint8)
        engine.coef[:] = coefs[3]
        engine.run(single, layers=[lay[3]])
        np.testing.assert_array_equal(single, want[3])
    finally:
        engine.close()


def test_reference_holds_the_colour_range_and_replicates_grey():
    rng = np.random.default_rng(3)
    model = _model(rng, 10, 12, 1)
    ref = DetailReference(model, shape=(10, 12, 4), channels=1, format="BGRA")
    frame = rng.integers(0, 256, (10, 12, 4), dtype=np.uint8)
    out = ref.apply(frame.copy(), ref.layers(0, 3, 4.0))
    grey = out[..., 0]
    assert (grey >= model.low[..., 0]).all() and (grey <= model.high[..., 0]).all()
    assert (out[..., 1] == grey).all() and (out[..., 2] == grey).all() and (out[..., 3] == 255).all()


@pytest.mark.parametrize("channels", [1, 3])
def test_colours_outside_the_set_get_no_detail(channels):
    rng = np.random.default_rng(4)
    frame = rng.integers(0, 256, (10, 12, 3), dtype=np.uint8)
    if channels == 1:
        frame[...] = frame[..., :1]
    lay = layers(6, (9, 14), 0, 3)
    none = DetailReference(
        _model(rng, 10, 12, channels, colours=np.zeros(32**3, np.uint8)), shape=(10, 12, 3), channels=channels
    )
    m = none.low, none.high
    np.testing.assert_array_equal(
        none.apply(frame, lay, out=np.empty_like(frame))[..., :channels], np.clip(frame[..., :channels], *m)
    )
    every = DetailReference(
        DetailModel(none.volume, none.gain, none.low, none.high, np.ones(32**3, np.uint8)),
        shape=(10, 12, 3),
        channels=channels,
    )
    out = every.apply(frame, lay, out=np.empty_like(frame))
    assert (out[..., :channels] != np.clip(frame[..., :channels], *m)).any()


def test_layers_keep_the_variance_and_move_on():
    for life in (2, 8, 32):
        seen = set()
        for f in range(3 * life):
            a, b = layers(life, (16, 20), 5, f)
            assert a[3] ** 2 + b[3] ** 2 == pytest.approx(1.0, abs=1e-6)
            assert 0 <= a[0] < life and 0 <= a[1] < 16 and 0 <= a[2] < 20
            seen.add(a[1:3])
        assert len(seen) >= 2  # reborn at new offsets
    assert layers(32, (16, 20), 5, 7) == layers(32, (16, 20), 5, 7)
    assert layers(32, (16, 20), 5, 7) != layers(32, (16, 20), 6, 7)


@pytest.fixture(scope="module")
def detail_db(tmp_path_factory):
    clip = load_clip(wave_clip(t=60, h=24, w=32, seed=2))
    path = tmp_path_factory.mktemp("detail") / "d.h5"
    with DatabaseWriter(path) as w:
        w.put_texture("d", clip.source_info())
        w.put_method("d", "lds", learn_lds(clip, n=4))
    return path, clip.frames


def test_lds_plays_its_detail_on_both_backends(detail_db, cl_device):
    path, frames = detail_db
    with (
        open_player(path, seed=2, backend="opencl", device=cl_device) as pc,
        open_player(path, seed=2, backend="numpy") as pn,
    ):
        assert pc.detail_engine is not None and pn.detail_engine is not None
        for _ in range(10):
            a, b = pc.next_frame(), pn.next_frame()
            diff = np.abs(a.astype(int) - b)
            assert diff.max() <= 1 and (diff > 0).mean() <= 1e-3
        low, high = pn.detail_engine.low, pn.detail_engine.high
        assert (b >= low).all() and (b <= high).all()


def test_detail_control_scales_and_zero_leaves_the_projection(detail_db):
    path, _ = detail_db
    with open_player(path, seed=2, backend="numpy") as p:
        x = p.state
        plain = p.render_state(x)
        p.detail = 0.0
        no_detail = p.render_state(x)
        p.detail = 3.0
        strong = p.render_state(x)
        p.detail_engine = None  # the projection alone, for comparison
        bare = p.render_state(x)
    lo, hi = p_low_high(path)
    np.testing.assert_array_equal(no_detail, np.clip(bare, lo, hi))
    d1 = np.abs(plain.astype(int) - no_detail).mean()
    d3 = np.abs(strong.astype(int) - no_detail).mean()
    assert 0 < d1 < d3


def p_low_high(path):
    with h5py.File(path) as f:
        g = f["textures/d/lds/detail"]
        return g["low"][()], g["high"][()]


def test_database_without_detail_still_plays(detail_db, tmp_path):
    path, _ = detail_db
    old = tmp_path / "old.h5"
    old.write_bytes(path.read_bytes())
    with h5py.File(old, "a") as f:
        del f["textures/d/lds/detail"]
    with open_player(old, seed=2, backend="numpy") as p:
        assert p.detail_engine is None
        assert p.next_frame().shape == (24, 32, 3)
