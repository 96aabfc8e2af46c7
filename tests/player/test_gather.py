"""The shared gather machinery: OpenCL kernels against their numpy references."""

from __future__ import annotations

import numpy as np
import pytest

from dynatex.player.engines.gather import (
    gather_reference,
    gaussian_smooth,
    gaussian_weights,
    open_gather,
    pack_source,
    time_units,
    unpack_source,
    wrap_index,
)


def _need_wide(ctx, wide=True):
    """Skip where the x86 variant is asked for but did not pass this device's self-test."""
    from dynatex.player.opencl.context import variant_verified

    if wide and not variant_verified(ctx.devices[0], "gather_wide"):
        pytest.skip(f"the gather_wide variant is not verified on {ctx.devices[0].name}")


def _stack(n=7, h=10, w=12, seed=0):
    return np.random.default_rng(seed).integers(0, 256, (n, h, w, 3), dtype=np.uint8)


def _close(a: np.ndarray, b: np.ndarray) -> None:
    diff = np.abs(a.astype(int) - b.astype(int))
    assert diff.max() <= 1, diff.max()
    assert (diff > 0).mean() < 0.01


def _render_both(cl_context, stack, size, tones, source, tmap, times, **options):
    """The frames at ``times`` of one setup (``source`` a cell grid when ``cell`` is among the
    options, else a per-pixel map) as (OpenCL, numpy) pairs, and the OpenCL Gather."""
    frames, gathers = {}, {}
    for backend in ("opencl", "numpy"):
        g = open_gather(stack, size, backend=backend, ctx=cl_context if backend == "opencl" else None, **options)
        g.set_tones(*tones)
        (g.set_source_grid if "cell" in options else g.set_source_map)(source)
        g.set_time_map(tmap)
        frames[backend], gathers[backend] = [g.render(t).copy() for t in times], g
    return list(zip(frames["opencl"], frames["numpy"])), gathers["opencl"]


def test_wrap_modes():
    i = np.arange(-5, 12)
    assert wrap_index(i, 4, "loop").tolist() == [(v % 4) for v in i]
    assert wrap_index(i, 4, "clamp").min() == 0 and wrap_index(i, 4, "clamp").max() == 3
    pp = wrap_index(np.arange(0, 12), 4, "pingpong").tolist()
    assert pp == [0, 1, 2, 3, 2, 1, 0, 1, 2, 3, 2, 1]
    with pytest.raises(ValueError, match="wrap"):
        wrap_index(i, 4, "bounce")


def test_pack_roundtrip_and_limits():
    idx = np.array([[0, 5], [2**24 - 1, 17]])
    tone = np.array([[0, 255], [3, 1]])
    got_i, got_t = unpack_source(pack_source(idx, tone))
    assert (got_i == idx).all() and (got_t == tone).all()
    with pytest.raises(ValueError, match="source index"):
        pack_source(np.array([2**24]))
    with pytest.raises(ValueError, match="tone"):
        pack_source(np.array([1]), 256)


def test_gaussian_smooth_reference_properties():
    assert gaussian_weights(0).tolist() == [1.0]
    w = gaussian_weights(2.0)
    assert len(w) == 13 and abs(float(w.sum()) - 1) < 1e-6
    m = np.zeros((9, 20), np.float32)
    m[:, 10:] = 6.0
    s = gaussian_smooth(m, 2.0)
    assert np.allclose(s[:, 0], 0, atol=1e-6) and np.allclose(s[:, -1], 6, atol=1e-5)
    assert (np.diff(s[4]) >= -1e-6).all() and 2.0 < s[4, 10] < 4.0  # monotone ramp
    assert np.allclose(gaussian_smooth(np.full((5, 5), 3.0), 1.5), 3.0, atol=1e-5)  # clamped edges keep constants


def test_identity_map_integer_time_is_exact_copy():
    stack = _stack()
    g = open_gather(stack, (10, 12), backend="numpy")
    g.set_source_map(pack_source(np.arange(120).reshape(10, 12)))
    for t in (0, 3, 8, -2):
        assert (g.render(float(t)) == stack[t % 7]).all()


@pytest.mark.parametrize("wrap", ["loop", "clamp", "pingpong"])
@pytest.mark.parametrize("interpolate", [True, False])
def test_map_gather_opencl_matches_numpy(cl_context, wrap, interpolate):
    stack = _stack()
    rng = np.random.default_rng(1)
    H, W = 23, 31
    packed = pack_source(rng.integers(0, 120, (H, W)), rng.integers(0, 2, (H, W)))
    tmap = rng.uniform(-3, 3, (H, W)).astype(np.float32)
    gains = np.array([[1, 1, 1], [1.1, 0.9, 1.2]], np.float32)
    offs = np.array([[0, 0, 0], [5, -3, 0]], np.float32)
    pairs, _ = _render_both(
        cl_context,
        stack,
        (H, W),
        (gains, offs),
        packed,
        tmap,
        (0.0, 2.25, 13.5, -4.75),
        wrap=wrap,
        interpolate=interpolate,
    )
    for a, b in pairs:
        _close(a, b)


def test_grid_gather_with_coarse_time_opencl_matches_numpy(cl_context):
    stack = _stack(n=9, h=8, w=24)  # three 8x8 "tiles" side by side
    H, W = 37, 45
    gh, gw = -(-H // 8), -(-W // 8)
    rng = np.random.default_rng(2)
    origins = pack_source(8 * rng.integers(0, 3, (gh, gw)), rng.integers(0, 3, (gh, gw)))
    step = 4
    th, tw = -(-H // step), -(-W // step)
    tmap = np.repeat(np.repeat(rng.integers(0, 5, (gh, gw)).astype(np.float32), 2, 0), 2, 1)[:th, :tw]
    out = {}
    for backend in ("opencl", "numpy"):
        g = open_gather(
            stack, (H, W), backend=backend, ctx=cl_context if backend == "opencl" else None, cell=(8, 8), time_step=step
        )
        g.set_tones(np.array([[1, 1, 1], [0.5, 0.5, 0.5], [1.5, 1, 1]], np.float32))
        g.set_source_grid(origins)
        g.set_time_map(tmap)
        g.smooth_time_map(6.0)
        out[backend] = (g.render(5.3), g.time_map)
    assert np.allclose(out["opencl"][1], out["numpy"][1], atol=1e-4)
    _close(out["opencl"][0], out["numpy"][0])


def test_next_time_map_moves_the_target_in_and_smooths_only_the_new_one(cl_context):
    """``next_time_map``: the smoothed target becomes the map, the new target is smoothed where
    the maps are kept; the same maps as ``set_time_map`` of both then ``smooth_time_map``, on
    each backend, and the frames match the reference."""
    stack = _stack(n=9, h=32, w=64)
    rng = np.random.default_rng(5)
    H, W = 37, 130
    origins = pack_source(rng.integers(0, 2, (-(-H // 16), -(-W // 32))) * 32)
    maps = [rng.uniform(0, 6, (-(-H // 8), -(-W // 8))).astype(np.float32) for _ in range(3)]
    for backend in ("opencl", "numpy"):
        ctx = cl_context if backend == "opencl" else None
        moved, direct = (
            open_gather(stack, (H, W), backend=backend, ctx=ctx, cell=(16, 32), time_step=8) for _ in range(2)
        )
        for g in (moved, direct):
            g.set_source_grid(origins)
        moved.set_time_map(maps[0], maps[1])
        moved.smooth_time_map(12.0)
        moved.next_time_map(maps[2], 12.0)
        direct.set_time_map(maps[1], maps[2])
        direct.smooth_time_map(12.0)
        assert np.array_equal(moved.time_map, direct.time_map) and np.array_equal(moved.target_map, direct.target_map)
        assert not np.array_equal(moved.target_map, maps[2])  # smoothed
        for t, fade in ((0.5, 0.0), (3.3, 0.6)):
            assert np.array_equal(moved.render(t, fade=fade), moved.render_reference(t, fade=fade)), (backend, t)
        with pytest.raises(ValueError, match="target must have shape"):
            moved.next_time_map(maps[2][1:])
        single = open_gather(stack, (H, W), backend=backend, ctx=ctx, cell=(16, 32), time_step=8)
        with pytest.raises(ValueError, match="needs a target"):
            single.next_time_map(maps[2])
        for g in (moved, direct, single):
            g.close()


def test_grid_pixels_come_from_the_named_cell():
    stack = _stack(n=3, h=4, w=8)
    g = open_gather(stack, (4, 8), backend="numpy", cell=(4, 4), interpolate=False)
    g.set_source_grid(pack_source(np.array([[4, 0]])))
    f = g.render(1.0)
    assert (f[:, :4] == stack[1, :, 4:]).all() and (f[:, 4:] == stack[1, :, :4]).all()


def test_time_interpolation_halfway():
    stack = np.zeros((4, 1, 1, 3), np.uint8)
    stack[:, 0, 0, :] = np.array([0, 100, 200, 50])[:, None]
    g = open_gather(stack, (1, 1), backend="numpy")
    g.set_source_map(pack_source(np.zeros((1, 1), int)))
    assert int(g.render(0.5)[0, 0, 0]) == 50
    assert int(g.render(3.5)[0, 0, 0]) == 25  # loop: between frame 3 (50) and frame 0 (0)
    g.set_tones(np.array([2.0, 2.0, 2.0]), np.array([1.0, 0.0, -200.0]))
    px = g.render(1.0)[0, 0]
    assert px.tolist() == [201, 200, 0]


def test_fixed_point_is_within_one_grey_level_of_the_real_formula():
    """The integer blend and tone (module docstring) against round(((1-f) a + f b) gain + offset)."""
    rng = np.random.default_rng(0)
    stack = _stack(n=4, h=64, w=64)
    flat = stack.reshape(4, -1, 3).astype(np.float64)
    for _ in range(5):
        pix = rng.integers(0, 64 * 64, (128, 128))
        frames = rng.integers(-2, 6, (128, 128))
        weights = rng.integers(0, 256, (128, 128))
        tones = np.concatenate([rng.uniform(0, 1.5, (3, 3)), rng.uniform(-60, 60, (3, 3))], 1).astype(np.float32)
        tone = rng.integers(0, 3, (128, 128))
        got = gather_reference(stack, pix, tone, frames, weights, tones).astype(int)
        f = (weights / 255.0)[..., None]
        a, b = flat[frames % 4, pix], flat[(frames + 1) % 4, pix]
        exact = np.clip(np.rint((a + f * (b - a)) * tones[tone][..., :3] + tones[tone][..., 3:]), 0, 255)
        assert np.abs(got - exact).max() <= 1


def test_time_units_sample_the_map_bilinearly():
    """Frame and weight (255ths) of t + the map: exact at sample centres, bilinear between,
    within 1/255 of a frame of the real-valued interpolation, faded toward a target."""
    tmap = np.array([[0, 4], [8, 12]], np.float32)
    frame, weight = time_units(tmap, 0.0, (8, 8), 4)
    u = frame * 255 + weight
    assert u[0, 0] == 0 and u[1, 1] == 0 and u[-1, -1] == 12 * 255 and u[-2, -2] == 12 * 255
    yy, xx = np.mgrid[0:8, 0:8]
    fy, fx = np.clip((yy + 0.5) / 4 - 0.5, 0, 1), np.clip((xx + 0.5) / 4 - 0.5, 0, 1)
    real = 255 * (8 * fy + 4 * fx)
    assert np.abs(u - real).max() <= 1
    frame, weight = time_units(tmap, 2.25, (8, 8), 4, target=tmap + 4, fade=0.5)
    assert np.abs(frame * 255 + weight - (real + 255 * 4.25)).max() <= 1
    frame, weight = time_units(np.full((2, 2), -0.5, np.float32), 0.0, (2, 2), 1)
    assert (frame == -1).all() and (weight == 128).all()


@pytest.mark.parametrize("wide", [True, False])
def test_device_and_reference_agree_exactly(cl_context, wide):
    """Times are integers after one float32 rounding per map sample (the kernels turn off
    contraction), so every pixel matches the reference: any map, fade, time and step."""
    _need_wide(cl_context, wide)
    rng = np.random.default_rng(3)
    stack = _stack(n=9, h=32, w=64)
    # (150, 96): three work-items down the frame in the wide kernel, cell rows crossing bands
    for step, (h, w) in ((8, (37, 130)), (8, (64, 256)), (8, (150, 96)), (1, (20, 70)), (4, (37, 130))):
        if wide and step != 8:
            continue
        g = open_gather(stack, (h, w), backend="opencl", ctx=cl_context, cell=(16, 32), time_step=step, wide=wide)
        gh, gw = -(-h // 16), -(-w // 32)
        g.set_source_grid(pack_source(rng.integers(0, 2, (gh, gw)) * 32 + rng.integers(0, 2, (gh, gw)) * 16 * 64))
        th, tw = g.tmap_shape
        g.set_time_map(rng.uniform(-3, 6, (th, tw)).astype(np.float32), rng.uniform(0, 12, (th, tw)).astype(np.float32))
        g.set_tones(np.array([[1.2, 0.8, 1.0]], np.float32), np.array([[4, -6, 0]], np.float32))
        for t, fade in ((0.25, 0.0), (2.5, 0.3), (-4.75, 1.0), (7.1, 0.77)):
            assert np.array_equal(g.render(t, fade=fade), g.render_reference(t, fade=fade)), (step, h, w, t, fade)
        g.set_tones(np.ones((1, 3), np.float32))  # the identity
        assert np.array_equal(g.render(3.6, fade=0.5), g.render_reference(3.6, fade=0.5)), (step, h, w, "identity")
    # a per-pixel source: rows of consecutive pixels (the wide kernel's linear runs) and scattered ones
    g = open_gather(stack, (24, 192), backend="opencl", ctx=cl_context, time_step=8, wide=wide)
    index = (np.arange(24)[:, None] % 32) * 64 + np.arange(192)[None, :] % 64
    index[::3] = rng.integers(0, 32 * 64, (8, 192))
    g.set_tones(np.array([[1.0, 1.0, 1.0], [0.7, 1.1, 1.4]], np.float32))
    g.set_source_map(pack_source(index, (np.arange(192)[None, :] // 100).repeat(24, 0)))
    g.set_time_map(
        rng.uniform(0, 5, g.tmap_shape).astype(np.float32), rng.uniform(0, 5, g.tmap_shape).astype(np.float32)
    )
    for t, fade in ((0.5, 0.1), (3.3, 0.9)):
        assert np.array_equal(g.render(t, fade=fade), g.render_reference(t, fade=fade)), ("map", t, fade)


def test_bad_inputs_are_clear_errors():
    stack = _stack()
    with pytest.raises(ValueError, match="frames must be uint8"):
        open_gather(stack.astype(np.float32), (4, 4), backend="numpy")
    with pytest.raises(ValueError, match="wrap"):
        open_gather(stack, (4, 4), backend="numpy", wrap="mirror")
    g = open_gather(stack, (4, 4), backend="numpy")
    with pytest.raises(RuntimeError, match="set a source"):
        g.render(0)
    with pytest.raises(ValueError, match="packed must have shape"):
        g.set_source_map(pack_source(np.zeros((3, 4), int)))
    with pytest.raises(ValueError, match="outside"):
        g.set_source_map(pack_source(np.full((4, 4), 500)))
    with pytest.raises(ValueError, match="tone 1"):
        g.set_source_map(pack_source(np.zeros((4, 4), int), 1))
    with pytest.raises(ValueError, match="tmap must have shape"):
        g.set_time_map(np.zeros((3, 3)))
    with pytest.raises(ValueError, match="finite"):
        g.set_time_map(np.full((4, 4), np.nan))
    with pytest.raises(ValueError, match="target must lie within"):
        g.set_time_map(np.zeros((4, 4)), np.full((4, 4), 3000.0))
    with pytest.raises(ValueError, match="fade"):
        g.set_source_map(pack_source(np.arange(16).reshape(4, 4)))
        g.render(0.0, fade=1.5)
    with pytest.raises(ValueError, match="gain"):
        g.set_tones(np.array([[-1, 1, 1]]))
    with pytest.raises(ValueError, match="offset must be finite within"):
        g.set_tones(np.array([[1, 1, 1]]), np.array([[0, 300, 0]]))
    with pytest.raises(TypeError, match="wide"):
        open_gather(stack, (4, 4), backend="numpy", wide="yes")
    with pytest.raises(ValueError, match="sigma"):
        g.smooth_time_map(-1)
    gg = open_gather(stack, (4, 4), backend="numpy", cell=(4, 4))
    with pytest.raises(ValueError, match="reach outside"):
        gg.set_source_grid(pack_source(np.full((1, 1), 10)))
    with pytest.raises(ValueError, match="cell 11x4 is larger"):
        open_gather(stack, (4, 4), backend="numpy", cell=(11, 4))
    with pytest.raises(ValueError, match=r"out_size must be \(height, width\) with each side in 1\.\.16384"):
        open_gather(stack, (0, 4), backend="numpy")
    with pytest.raises(ValueError, match=r"cell must be \(height, width\), two integers"):
        open_gather(stack, (4, 4), backend="numpy", cell=(4,))
    with pytest.raises(TypeError, match=r"out_size must be \(height, width\) integers"):
        open_gather(stack, (4.0, 4), backend="numpy")


@pytest.mark.parametrize("cell", [(8, 8), (5, 7), (9, 40), (7, 64), (9, 72), (12, 100)])
@pytest.mark.parametrize("wrap", ["loop", "pingpong"])
def test_vector_path_time_step_8_grid_matches_numpy(cl_context, cell, wrap):
    """Time step 8 takes the 64-pixel runs: cell boundaries inside a run (two sources, two
    tones), cells narrower than a run (three sources: per-pixel fallback), a partial run at
    the row's end, runs whose frames span up to four neighbours and steep ones that span more."""
    ch, cw = cell
    stack = _stack(n=11, h=2 * ch, w=3 * cw)
    H, W = 29, 157
    gh, gw = -(-H // ch), -(-W // cw)
    rng = np.random.default_rng(3)
    origins = pack_source(
        rng.integers(0, 2, (gh, gw)) * ch * 3 * cw + cw * rng.integers(0, 3, (gh, gw)), rng.integers(0, 3, (gh, gw))
    )
    th, tw = -(-H // 8), -(-W // 8)
    tmap = (rng.uniform(-2, 2, (th, tw)) + np.linspace(0, 9, tw)[None, :]).astype(np.float32)
    tmap[:, 7] += 25.0  # steep: runs spanning several frames
    gains = np.array([[1, 1, 1], [0.8, 1.3, 0.5], [1.5, 0.7, 1.1]], np.float32)
    offs = np.array([[0, 0, 0], [4, -6, 10], [-3, 2, 0]], np.float32)
    pairs, _ = _render_both(
        cl_context,
        stack,
        (H, W),
        (gains, offs),
        origins,
        tmap,
        (0.0, 3.4, 7.999, -5.25),
        cell=cell,
        time_step=8,
        wrap=wrap,
    )
    for a, b in pairs:
        _close(a, b)


@pytest.mark.parametrize("wide", [True, False])
def test_time_step_8_kernels_agree_with_numpy_on_a_smooth_map(cl_context, wide):
    """The x86 variant (where verified) and the portable per-pixel kernel on the tiles mode's
    typical input: wide cells, a smooth map of several frames' range, tones per cell."""
    _need_wide(cl_context, wide)
    stack = _stack(n=20, h=40, w=3 * 90)
    H, W = 83, 64 * 5 + 17
    rng = np.random.default_rng(7)
    gh, gw = -(-H // 40), -(-W // 90)
    origins = pack_source(rng.integers(0, 3, (gh, gw)) * 90, rng.integers(0, 2, (gh, gw)))
    th, tw = -(-H // 8), -(-W // 8)
    tmap = gaussian_smooth(rng.uniform(0, 12, (th, tw)).astype(np.float32), 2.0)
    tones = (np.array([[1.1, 0.9, 1.0], [0.7, 1.2, 2.5]]), np.array([[2, -3, 0], [0, 5, -40]]))
    pairs, g = _render_both(
        cl_context, stack, (H, W), tones, origins, tmap, (0.0, 2.37, 13.9), cell=(40, 90), time_step=8, wide=wide
    )
    assert g.wide == wide
    for a, b in pairs:
        _close(a, b)


def test_vector_path_time_step_8_pixel_map_matches_numpy(cl_context):
    """Per-pixel map with time step 8: linear runs take the vector path, the rest go per pixel."""
    stack = _stack(n=6, h=12, w=40)
    H, W = 21, 203
    rng = np.random.default_rng(4)
    idx = (np.arange(H)[:, None] % 12) * 40 + (np.arange(W)[None, :] % 40)
    idx[rng.random((H, W)) < 0.02] = rng.integers(0, 480, int((rng.random((H, W)) < 0.02).sum()))[:1]
    packed = pack_source(idx, (np.arange(W)[None, :] // 50 % 2) * np.ones((H, 1), int))
    tmap = rng.uniform(0, 12, (-(-H // 8), -(-W // 8))).astype(np.float32)
    tones = (np.array([[1, 1, 1], [1.2, 0.9, 0.6]], np.float32), np.array([[0, 0, 0], [3, 0, -2]], np.float32))
    pairs, _ = _render_both(cl_context, stack, (H, W), tones, packed, tmap, (0.5, 4.75), time_step=8)
    for a, b in pairs:
        _close(a, b)


def test_render_writes_into_the_callers_array(cl_context):
    """On a device that shares host memory the frame lands in ``out`` without a copy; either way
    ``out`` holds the frame, also when it is a view into a larger array."""
    stack = _stack(n=5, h=8, w=24)
    g = open_gather(stack, (19, 45), backend="opencl", ctx=cl_context, cell=(8, 8), time_step=8)
    g.set_source_grid(pack_source(np.full((3, 6), 8)))
    from dynatex.player.opencl.programs import device_shares_host_memory

    assert g.direct == device_shares_host_memory(cl_context)
    fresh = g.render(2.5).copy()
    big = np.zeros((2, 19, 45, 3), np.uint8)
    got = g.render(2.5, out=big[1])
    assert got is big[1] or np.shares_memory(got, big)
    assert (big[1] == fresh).all() and (big[0] == 0).all()
    _close(fresh, g.render_reference(2.5))


def test_frame_traffic_counts_output_and_distinct_stored_pixels():
    """bytes_per_frame = the output written once + each distinct (frame, pixel) read once."""
    stack = _stack(n=6, h=8, w=16)  # two 8x8 cells side by side
    g = open_gather(stack, (16, 40), backend="numpy", cell=(8, 8), time_step=8)
    g.set_source_grid(pack_source(np.zeros((2, 5), int)))  # one cell repeated everywhere
    g.render(2.0)
    assert g.frame_traffic() == {"output": 16 * 40 * 3, "stored": 2 * 64 * 3}  # frames 2 and 3
    tmap = np.zeros(g.tmap_shape, np.float32)
    tmap[:, 3:] = 2.0  # part of the frame two frames later
    g.set_time_map(tmap)
    assert g.frame_traffic(2.0)["stored"] == 4 * 64 * 3  # frames 2..5, each once
    assert g.bytes_per_frame == sum(g.frame_traffic().values())
    m = open_gather(stack, (8, 16), backend="numpy", interpolate=False)
    m.set_source_map(pack_source(np.arange(128).reshape(8, 16)))
    assert m.frame_traffic(0.0)["stored"] == 128 * 3  # every output pixel its own source


def test_frames_land_in_whichever_array_comes_and_nowhere_else(cl_context):
    """The buffer wrapping a caller's array is reused while that array comes back; switching
    arrays, or rendering on the device in between, must not write into an array passed before."""
    stack = _stack(n=6, h=16, w=64)
    g = open_gather(stack, (37, 130), backend="opencl", ctx=cl_context, cell=(16, 32), time_step=8)
    g.set_source_grid(pack_source(np.arange(3 * 5).reshape(3, 5) % 2 * 32))
    g.set_time_map(np.linspace(0, 3, 5 * 17, dtype=np.float32).reshape(5, 17))
    a, b = np.zeros((37, 130, 3), np.uint8), np.zeros((37, 130, 3), np.uint8)
    for t, target in ((0.5, a), (1.25, a), (2.0, b), (2.75, None), (3.5, a), (4.0, b)):
        before = (a.copy(), b.copy())
        if target is None:
            g.render_on_device(t)
        else:
            g.render(t, out=target)
            _close(target, g.render_reference(t))
        for arr, old in zip((a, b), before):
            if arr is not target:
                assert np.array_equal(arr, old)


def test_a_device_without_the_verified_variant_gets_the_portable_kernel(cl_context, monkeypatch):
    """Where the self-test did not verify the x86 variant, time step 8 renders with the portable
    kernel (the same integers), and asking for the variant is an error that says why."""
    import dynatex.player.opencl.context as ocl

    monkeypatch.setattr(ocl, "variant_verified", lambda device, variant: False)
    stack = _stack(n=5, h=16, w=64)
    g = open_gather(stack, (20, 70), backend="opencl", ctx=cl_context, cell=(16, 32), time_step=8)
    assert not g.wide
    g.set_source_grid(pack_source(np.zeros((2, 3), int)))
    g.set_time_map(np.linspace(0, 2, 3 * 9, dtype=np.float32).reshape(3, 9))
    assert np.array_equal(g.render(1.3), g.render_reference(1.3))
    with pytest.raises(ocl.OpenCLUnavailableError, match="gather_wide variant is not verified"):
        open_gather(stack, (20, 70), backend="opencl", ctx=cl_context, cell=(16, 32), time_step=8, wide=True)


@pytest.mark.parametrize("wide", [True, False])
def test_a_weight_rounding_up_to_255_is_the_next_frame(cl_context, wide):
    """At t = 0.999 the weight rounds to 255/255: the pixel is frame 1 itself, in both kernels
    (found in review: the wide kernel once held such lanes at weight 255 on frame 0)."""
    _need_wide(cl_context, wide)
    stack = np.zeros((3, 8, 64, 3), np.uint8)
    stack[1:] = 255
    g = open_gather(stack, (16, 128), backend="opencl", ctx=cl_context, cell=(8, 64), time_step=8, wide=wide)
    g.set_source_grid(pack_source(np.zeros((2, 2), int)))
    for t in (0.999, 1.999, 2.999, 0.9985):
        got = g.render(t)
        assert np.array_equal(got, g.render_reference(t)), (t, np.unique(got))


def test_switching_between_identity_and_real_tones(cl_context):
    """Setting a real tone, and back to the identity, must take effect at the next frame (the
    wide kernel loads a segment's tone once, before its rows)."""
    stack = _stack(n=6, h=16, w=64)
    g = open_gather(stack, (24, 128), backend="opencl", ctx=cl_context, cell=(16, 64), time_step=8)
    g.set_source_grid(pack_source(np.zeros((2, 2), int)))
    g.set_time_map(np.linspace(0, 3, 3 * 16, dtype=np.float32).reshape(3, 16))
    for gain, offset in (([1, 1, 1], [0, 0, 0]), ([1.3, 0.6, 1.0], [5, -9, 0]), ([1, 1, 1], [0, 0, 0])):
        g.set_tones(np.array([gain], np.float32), np.array([offset], np.float32))
        _close(g.render(2.6), g.render_reference(2.6))


@pytest.mark.parametrize("offset", [0, 16, 32, 48, 3])
def test_frames_land_whatever_the_arrays_alignment(cl_context, offset):
    """Rows a multiple of 64 bytes long: the wide kernel shifts its runs so that their stores
    are 64-byte aligned (non-temporal) for an array 16, 32 or 48 bytes off 64, and stores
    plainly otherwise (3 bytes off). Every pixel must match the reference either way."""
    stack = _stack(n=6, h=16, w=64)
    h, w = 37, 256  # 768-byte rows
    g = open_gather(stack, (h, w), backend="opencl", ctx=cl_context, cell=(16, 32), time_step=8)
    g.set_source_grid(pack_source((np.arange(3 * 8).reshape(3, 8) % 3) * 16))
    g.set_time_map(np.linspace(0, 3, 5 * 32, dtype=np.float32).reshape(5, 32))
    g.set_tones(np.array([[1.2, 0.8, 1.0]], np.float32), np.array([[4, -6, 0]], np.float32))
    raw = np.zeros(h * w * 3 + 128, np.uint8)
    start = (-raw.ctypes.data) % 64 + offset
    out = raw[start : start + h * w * 3].reshape(h, w, 3)
    assert out.ctypes.data % 64 == offset
    for t in (0.25, 2.5, 4.75):
        g.render(t, out=out)
        _close(out, g.render_reference(t))
    assert not raw[:start].any() and not raw[start + h * w * 3 :].any()  # nothing outside the array


def test_the_wide_kernels_plain_vector_code_computes_the_same_integers(cl_context, monkeypatch):
    """Where the compiler does not target AVX-512BW the wide variant blends, packs and divides
    with plain vector code instead of x86 builtins; forced here (PORTABLE=1), it must still
    match the reference exactly."""
    import dynatex.player.opencl.programs as ocl

    _need_wide(cl_context)
    real = ocl.build_program
    monkeypatch.setattr(
        ocl, "build_program", lambda ctx, name, defines=None: real(ctx, name, {**(defines or {}), "PORTABLE": 1})
    )
    rng = np.random.default_rng(5)
    stack = _stack(n=7, h=16, w=64)
    g = open_gather(stack, (40, 256), backend="opencl", ctx=cl_context, cell=(16, 32), time_step=8)
    assert g.wide
    g.set_source_grid(pack_source(rng.integers(0, 2, (3, 8)) * 32))
    g.set_time_map(rng.uniform(0, 4, g.tmap_shape).astype(np.float32))
    g.set_tones(np.array([[1.3, 0.7, 1.0]], np.float32), np.array([[9, -4, 0]], np.float32))
    for t in (0.4, 3.9):
        assert np.array_equal(g.render(t), g.render_reference(t))


def test_clamped_time_far_beyond_the_ends_holds_the_end_frames(cl_context):
    """With wrap="clamp" any time past the ends shows the end frames; huge times must neither
    overflow the integer time nor differ from the reference."""
    stack = _stack(n=5, h=16, w=64)
    g = open_gather(stack, (16, 128), backend="opencl", ctx=cl_context, cell=(16, 64), time_step=8, wrap="clamp")
    g.set_source_grid(pack_source(np.zeros((1, 2), int)))
    for t, frame in ((1e12, 4), (-1e12, 0), (4.0 + 3000, 4)):
        got = g.render(t)
        assert np.array_equal(got, g.render_reference(t))
        assert np.array_equal(got[:, :64], stack[frame])
