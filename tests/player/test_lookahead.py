"""k frames per pass over the basis (``lookahead``): the same frames as one at a time within the
projection's tolerance, on both backends, with the detail and without; a control change applies
to the next frame; get_state/set_state stay exact."""

from __future__ import annotations

import numpy as np
import pytest

from dynatex.analyzer import load_clip
from dynatex.analyzer.lds import learn_lds
from dynatex.analyzer.mixture import learn_mixture
from dynatex.errors import InvalidArgumentError
from dynatex.player import open_player
from dynatex.player.engines.projection import open_projector
from dynatex.tiledb import DatabaseWriter

from ..conftest import wave_clip

#: float32 sums in another order (a GEMM against one product at a time, a kernel against
#: BLAS) may round a value to the neighbouring integer, on a small share of values
MAX_LEVEL_DIFF = 1
MAX_DIFF_SHARE = 2e-3


def assert_close(a: np.ndarray, b: np.ndarray) -> None:
    d = np.abs(a.astype(int) - b)
    assert d.max() <= MAX_LEVEL_DIFF and (d > 0).mean() <= MAX_DIFF_SHARE


@pytest.fixture(scope="module")
def dbs(tmp_path_factory):
    """An lds texture (with its detail) and a mixture texture of the same small clip."""
    clip = load_clip(wave_clip(t=80, h=24, w=40, seed=4))
    path = tmp_path_factory.mktemp("ahead") / "a.h5"
    with DatabaseWriter(path) as w:
        w.put_texture("waves", clip.source_info())
        w.put_method("waves", "lds", learn_lds(clip, n=6))
        w.put_method("waves", "mixture", learn_mixture(clip, components=2, dim=4, pca_dim=16, neighbors=8, pmax=3))
    return path


def check_k_frames(path, mode: str, detail: bool, backend: str, device) -> None:
    kw = {"mode": mode, "seed": 5, "backend": backend, "device": device}
    with open_player(path, **kw) as one, open_player(path, lookahead=4, **kw) as ahead:
        assert one.backend == ahead.backend == backend
        assert (one.detail_engine is not None) == (ahead.detail_engine is not None)
        if not detail:
            one.detail_engine = ahead.detail_engine = None
        frames_one = [one.next_frame() for _ in range(11)]
        frames_ahead = [ahead.next_frame() for _ in range(11)]
        assert one.get_state()["frame_index"] == ahead.get_state()["frame_index"] == 11
    for a, b in zip(frames_one, frames_ahead):
        assert_close(a, b)
    assert any(not np.array_equal(frames_one[0], f) for f in frames_one[1:])  # frames move


@pytest.mark.parametrize("mode", ["lds", "mixture"])
@pytest.mark.parametrize("detail", [True, False], ids=["detail", "alone"])
def test_k_frames_per_pass_are_the_frames_one_at_a_time_numpy(dbs, mode, detail):
    check_k_frames(dbs, mode, detail, "numpy", None)


@pytest.mark.parametrize("mode", ["lds", "mixture"])
@pytest.mark.parametrize("detail", [True, False], ids=["detail", "alone"])
def test_k_frames_per_pass_are_the_frames_one_at_a_time_opencl(dbs, cl_device, mode, detail):
    check_k_frames(dbs, mode, detail, "opencl", cl_device)


def test_engine_gemm_equals_one_product_at_a_time(cl_context):
    """The engines' k-frame pass against their own single-frame runs, both backends."""
    import pyopencl as cl

    rng = np.random.default_rng(2)
    h, w, n = 19, 45, 9
    basis = (rng.standard_normal((n, h * w * 3)) * 20).astype(np.float32)
    mean = rng.uniform(0, 255, h * w * 3).astype(np.float32)
    for ctx in (None, cl_context):
        e = open_projector(
            basis, mean, shape=(h, w, 3), channels=3, ctx=ctx, queue=ctx and cl.CommandQueue(ctx), frames=6
        )
        try:
            e.coefs[:] = rng.standard_normal((6, n))
            coefs = e.coefs.copy()
            many = np.empty((6, h, w, 3), np.uint8)
            e.run(many, count=6)
            for j in range(6):
                e.coef[:] = coefs[j]
                assert_close(e.run(one := np.empty((h, w, 3), np.uint8)) or one, many[j])
        finally:
            e.close()


def test_basis_in_row_blocks_and_slabs_is_the_basis_at_once(cl_context, monkeypatch):
    """A basis given as row blocks (the mixture's stacked rows and its residual's) and laid out on
    the device a few groups at a time gives the bytes of the one array laid out at once, and both
    backends agree."""
    import pyopencl as cl

    from dynatex.player.engines import projection

    rng = np.random.default_rng(5)
    h, w, n = 21, 50, 9  # 1050 pixels: 65 full groups of 16 and a partial one
    basis = (rng.standard_normal((n, h * w * 3)) * 20).astype(np.float32)
    mean = rng.uniform(0, 255, h * w * 3).astype(np.float32)
    coefs = rng.standard_normal((3, n)).astype(np.float32)
    frames = {}
    for name, rows, slab in (("whole", basis, 1 << 30), ("blocks", (basis[:5], basis[5:]), 3 * 9 * 48 * 4 + 1)):
        monkeypatch.setattr(projection, "SLAB_BYTES", slab)
        for ctx in (None, cl_context):
            e = open_projector(
                rows, mean, shape=(h, w, 3), channels=3, ctx=ctx, queue=ctx and cl.CommandQueue(ctx), frames=3
            )
            try:
                e.coefs[:] = coefs
                frames[name, ctx is None] = out = np.empty((3, h, w, 3), np.uint8)
                e.run(out, count=3)
            finally:
                e.close()
    np.testing.assert_array_equal(frames["blocks", False], frames["whole", False])
    np.testing.assert_array_equal(frames["blocks", True], frames["whole", True])
    assert_close(frames["blocks", False], frames["blocks", True])


def check_control_change(path, mode: str, backend: str, device) -> None:
    control, value = ("speed", -0.5) if mode == "lds" else ("intensity", 2.5)
    kw = {"mode": mode, "seed": 1, "backend": backend, "device": device}
    with open_player(path, **kw) as one, open_player(path, lookahead=8, **kw) as ahead:
        for p in (one, ahead):
            for _ in range(3):
                p.next_frame()
            setattr(p, control, value)  # mid-pass for the look-ahead player: 5 frames discarded
        for _ in range(12):
            assert_close(one.next_frame(), ahead.next_frame())
        assert getattr(ahead, control) == value


def check_state_mid_pass(path, mode: str, backend: str, device) -> None:
    kw = {"mode": mode, "seed": 3, "backend": backend, "device": device}
    with open_player(path, **kw) as one, open_player(path, lookahead=6, **kw) as ahead:
        for _ in range(4):
            one.next_frame()
            ahead.next_frame()
        s1, s2 = one.get_state(), ahead.get_state()  # 2 frames of the look-ahead's pass not handed out
        assert s1.keys() == s2.keys()
        for key in s1:
            if isinstance(s1[key], np.ndarray):
                np.testing.assert_array_equal(s1[key], s2[key])
            else:
                assert s1[key] == s2[key], key
        later = [ahead.next_frame() for _ in range(9)]
        ahead.set_state(s2)
        again = [ahead.next_frame() for _ in range(9)]
        for a, b in zip(later, again):
            assert_close(a, b)
        with open_player(path, mode=mode, backend="numpy") as fresh:
            fresh.set_state(s2)
            assert_close(fresh.next_frame(), later[0])


@pytest.mark.parametrize("mode", ["lds", "mixture"])
def test_a_control_change_applies_to_the_next_frame_numpy(dbs, mode):
    check_control_change(dbs, mode, "numpy", None)


@pytest.mark.parametrize("mode", ["lds", "mixture"])
def test_state_mid_pass_is_exact_and_restores_numpy(dbs, mode):
    check_state_mid_pass(dbs, mode, "numpy", None)


@pytest.mark.parametrize("mode", ["lds", "mixture"])
def test_control_and_state_with_a_pass_in_flight_opencl(dbs, cl_device, mode):
    """On OpenCL the next pass renders while one is handed out: two passes ahead, still exact."""
    check_control_change(dbs, mode, "opencl", cl_device)
    check_state_mid_pass(dbs, mode, "opencl", cl_device)


def test_state_property_and_advance_see_the_frames_handed_out(dbs):
    with (
        open_player(dbs, mode="lds", seed=2, backend="numpy") as one,
        open_player(dbs, mode="lds", seed=2, backend="numpy", lookahead=5) as ahead,
    ):
        for p in (one, ahead):
            p.next_frame()
            p.next_frame()
        np.testing.assert_array_equal(one.state, ahead.state)
        one.advance(3)
        ahead.advance(3)
        np.testing.assert_array_equal(one.state, ahead.state)
        assert_close(one.next_frame(), ahead.next_frame())


@pytest.mark.parametrize("value", [0, 65, 2.5, "8"])
def test_bad_lookahead(dbs, value):
    with pytest.raises(InvalidArgumentError, match="lookahead"):
        open_player(dbs, mode="lds", backend="numpy", lookahead=value)
