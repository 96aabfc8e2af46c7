"""RGBA and BGRA frames: written by every mode's kernels (alpha 255, colours in place), equal to
the RGB frames placed by the reference, on every verified device and on numpy."""

from __future__ import annotations

import numpy as np
import pytest

from dynatex.player import open_player
from dynatex.player.engines.gather import open_gather, pack_source
from dynatex.player.opencl import selftest
from dynatex.player.pixels import FORMATS, pixel_format

MODES = [
    ("lds", {}),
    ("lds", {"precision": "float16"}),
    ("mixture", {}),
    ("turnpoints", {"playback": "jumps"}),
    ("turnpoints", {"playback": "hybrid"}),
    ("tiles", {"size": (72, 40)}),
    ("tiles", {"size": (50, 37)}),
    ("evolve", {"jitter": 2.0}),
]
IDS = ["lds", "lds-f16", "mixture", "turnpoints-jumps", "turnpoints-hybrid", "tiles", "tiles-odd", "evolve"]


def test_formats_place_the_colours():
    rgb = np.array([[[1, 2, 3], [4, 5, 6]]], np.uint8)
    assert np.array_equal(FORMATS["RGB"].from_rgb(rgb), rgb)
    assert FORMATS["RGBA"].from_rgb(rgb).tolist() == [[[1, 2, 3, 255], [4, 5, 6, 255]]]
    assert FORMATS["BGRA"].from_rgb(rgb).tolist() == [[[3, 2, 1, 255], [6, 5, 4, 255]]]
    assert pixel_format("BGRA") is FORMATS["BGRA"]
    with pytest.raises(ValueError, match=r"format must be one of \('RGB', 'RGBA', 'BGRA'\), not 'ARGB'"):
        pixel_format("ARGB")


@pytest.mark.parametrize("fmt", ["RGBA", "BGRA"])
@pytest.mark.parametrize("mode, options", MODES, ids=IDS)
def test_every_mode_writes_each_format(cl_device, mode, options, fmt):
    """next_frame and start_frame (frame in flight) in ``fmt`` equal the RGB frames placed by
    the reference, on the device and on numpy."""
    db = selftest._db_path()
    for backend, device in (("opencl", cl_device), ("numpy", None)):
        with (
            open_player(db, selftest.TEXTURE, mode=mode, backend=backend, device=device, seed=5, **options) as rgb,
            open_player(
                db, selftest.TEXTURE, mode=mode, backend=backend, device=device, seed=5, format=fmt, **options
            ) as p,
        ):
            assert p.shape == rgb.shape[:2] + (4,) and p.format.name == fmt
            for k in range(4):
                want = FORMATS[fmt].from_rgb(rgb.next_frame())
                if k % 2:
                    got = p.next_frame()
                else:
                    got = p.start_frame(np.zeros(p.shape, np.uint8)).wait()
                assert np.array_equal(got, want), (backend, mode, fmt, k)
        with pytest.raises(ValueError, match=r"out must be uint8 with shape"):
            open_player(db, selftest.TEXTURE, mode=mode, backend="numpy", seed=5, format=fmt, **options).next_frame(
                np.empty(rgb.shape, np.uint8)
            )


@pytest.mark.parametrize("fmt", ["RGBA", "BGRA"])
@pytest.mark.parametrize("step, cell", [(1, None), (8, (8, 8)), (8, None)])
def test_gather_writes_each_format(cl_context, fmt, step, cell):
    """The gather kernel's own placement, per-pixel maps and cells, against its reference."""
    rng = np.random.default_rng(3)
    stack = rng.integers(0, 256, (5, 16, 24, 3), dtype=np.uint8)
    size = (19, 45)
    gain = rng.uniform(0.5, 1.5, (2, 3)).astype(np.float32)
    offset = rng.uniform(-20, 20, (2, 3)).astype(np.float32)
    idx = rng.integers(0, 16 * 24, size)
    gs = [
        open_gather(
            stack, size, backend=b, ctx=cl_context if b == "opencl" else None, time_step=step, cell=cell, format=fmt
        )
        for b in ("opencl", "numpy")
    ]
    for g in gs:
        assert g.out_shape == (19, 45, 4)
        g.set_tones(gain, offset)
        if cell is None:
            g.set_source_map(pack_source(idx, 1))
        else:
            g.set_source_grid(pack_source(np.zeros((3, 6), int), 1))
        g.set_time_map(np.linspace(-3, 3, np.prod(g.tmap_shape), dtype=np.float32).reshape(g.tmap_shape))
    for t in (0.0, 1.4, 7.75):
        got = gs[0].render(t)
        assert np.array_equal(got, gs[1].render(t)) and np.array_equal(got, gs[0].render_reference(t)), t
        assert (got[..., 3] == 255).all()
    gs[0].close()


@pytest.mark.parametrize("fmt", ["RGB", "RGBA", "BGRA"])
@pytest.mark.parametrize(
    "size, cell, misalign", [((40, 256), (8, 12), 0), ((33, 272), (8, 16), 32), ((40, 141), None, 16)]
)
def test_wide_variant_writes_each_format(cl_device, fmt, size, cell, misalign):
    """The x86 variant (where verified) writes every format itself: full runs with
    non-temporal stores (rows a multiple of 64 bytes, the array 0 or 32 bytes off 64), the
    head run and tails, against the reference."""
    from dynatex.player.opencl.context import get_context, variant_verified

    device = get_context(cl_device).devices[0]
    if not variant_verified(device, "gather_wide"):
        pytest.skip(f"gather_wide is not verified on {device.name}")
    check = selftest._gather_check(
        cell=cell, time_step=8, wrap="loop", size=size, wide=True, format=fmt, misalign=misalign
    )
    assert check(cl_device) is None


@pytest.mark.parametrize("fmt", ["RGB", "RGBA", "BGRA"])
@pytest.mark.parametrize("size, channels, half", [((7, 11), 3, False), ((16, 24), 3, True), ((5, 9), 1, False)])
def test_projection_writes_each_format(cl_context, fmt, size, channels, half):
    """Kernel project against its reference in every format: colour in a 4-byte format goes
    16 pixels per work-item (here whole groups, and 77 or 45 pixels: a partial last group)."""
    import pyopencl as cl

    from dynatex.player.engines.projection import open_projector

    h, w = size
    rng = np.random.default_rng(6)
    basis = (rng.standard_normal((7, h * w * channels)) * 40).astype(np.float16 if half else np.float32)
    mean = rng.uniform(0, 255, h * w * channels).astype(np.float32)
    shape = (h, w, FORMATS[fmt].bytes)
    ref = open_projector(basis, mean, shape=shape, channels=channels, format=fmt)
    dev = open_projector(
        basis, mean, shape=shape, channels=channels, ctx=cl_context, queue=cl.CommandQueue(cl_context), format=fmt
    )
    for k in range(3):
        ref.coef[:] = dev.coef[:] = rng.standard_normal(7)
        got, want = np.zeros(shape, np.uint8), np.zeros(shape, np.uint8)
        dev.run(got)
        ref.run(want)
        # float paths: rounding may differ by one level in a few values (as the self-test allows)
        d = np.abs(got.astype(int) - want.astype(int))
        assert d.max() <= 1 and (d > 0).mean() < 0.01, (fmt, k)
        if fmt != "RGB":
            assert (got[..., 3] == 255).all()
    dev.close()
