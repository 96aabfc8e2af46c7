"""Out-of-core learning: a clip on disk, read by pixel columns, gives the in-memory model."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from dynatex.analyzer import lds as lds_mod
from dynatex.analyzer import load_clip
from dynatex.analyzer.lds import learn_lds
from dynatex.analyzer.mixture import learn_mixture
from dynatex.analyzer.stream import ClipError, parse_bytes, spill_clip
from dynatex.errors import InvalidArgumentError

from .subspace import alignment, assert_same_lds


def _waves(t: int = 64, h: int = 48, w: int = 64, seed: int = 0) -> np.ndarray:
    """Travelling waves of distinct energies plus a little noise: a well separated spectrum."""
    rng = np.random.default_rng(seed)
    tt = np.arange(t)[:, None, None, None]
    yy = np.arange(h)[None, :, None, None]
    xx = np.arange(w)[None, None, :, None]
    cc = np.arange(3)[None, None, None, :]
    f = (
        128
        + 50 * np.sin(0.31 * tt + 0.20 * xx + 0.5 * cc)
        + 25 * np.sin(0.17 * tt - 0.23 * yy)
        + 12 * np.cos(0.53 * tt + 0.11 * (xx + yy))
        + 6 * np.sin(0.71 * tt + 0.3 * xx - 0.2 * yy)
        + rng.normal(0, 2, (t, h, w, 3))
    )
    return np.clip(np.rint(f), 0, 255).astype(np.uint8)


def _bound_for_columns(t: int, pixels: int, rows: int, columns: int) -> int:
    fixed = lds_mod.BASE_MEMORY + 2 * rows * pixels * 4 + 3 * pixels * 4 + 4 * t * t * 8
    return fixed + columns * (t * 5 + rows * 4 + 4)


@pytest.fixture
def waves_npy(tmp_path):
    frames = _waves()
    path = tmp_path / "waves.npy"
    np.save(path, frames)
    return path, frames


def test_npy_is_read_in_place_with_load_clips_hash(waves_npy):
    path, frames = waves_npy
    disk = spill_clip(path)
    assert not disk.owned and disk.path == str(path)
    assert disk.sha256 == load_clip(frames).sha256
    assert np.array_equal(disk.frames(), frames)
    cols = disk.columns(100, 700)
    assert np.array_equal(cols, frames.reshape(len(frames), -1)[:, 100:700])


def test_video_spill_matches_load_clip_and_is_removed(tmp_path):
    frames = _waves(t=20, h=32, w=40)
    path = str(tmp_path / "w.avi")
    out = cv2.VideoWriter(path, cv2.VideoWriter_fourcc(*"FFV1"), 25, (40, 32))
    for f in frames:
        out.write(cv2.cvtColor(f, cv2.COLOR_RGB2BGR))
    out.release()
    ref = load_clip(path, start=2, step=2, size=(16, 20))
    with spill_clip(path, folder=str(tmp_path), start=2, step=2, size=(16, 20)) as disk:
        assert disk.owned
        assert np.array_equal(disk.frames(), ref.frames)
        assert disk.source_info() == ref.source_info()
        spilled = disk.path
    assert not (tmp_path / spilled).exists()


def test_streamed_lds_equals_in_memory_lds(waves_npy):
    path, frames = waves_npy
    t, pixels = frames.shape[0], frames[0].size
    ref = learn_lds(frames, n=8)
    model = learn_lds(spill_clip(path), n=8, max_memory=_bound_for_columns(t, pixels, 8, 1500))
    assert model.info["column_blocks"] >= 6 and model.info["svd"] == "gram-streamed"
    # Documented tolerance (README): basis and states to 1e-4 relative, A and Q to 1e-4.
    assert np.array_equal(model.mean, ref.mean)
    np.testing.assert_allclose(model.singular_values[:8], ref.singular_values[:8], rtol=1e-5)
    assert_same_lds(model, ref, tol=1e-4)


def test_streamed_auto_order_matches(waves_npy):
    path, frames = waves_npy
    ref = learn_lds(frames, n="auto", energy=0.95)
    model = learn_lds(spill_clip(path), n="auto", energy=0.95)
    assert model.n == ref.n
    alignment(model.basis, ref.basis, ref.singular_values, tol=1e-4)


def test_streamed_mixture_pca_stage_equals_in_memory(waves_npy):
    path, frames = waves_npy
    kw = {"components": 2, "dim": 3, "pca_dim": 8, "neighbors": 8, "pmax": 2}
    ref = learn_mixture(frames, **kw)
    model = learn_mixture(spill_clip(path), **kw)
    np.testing.assert_allclose(model.singular_values, ref.singular_values, rtol=1e-5)
    np.testing.assert_allclose(model.stacked_basis, ref.stacked_basis, atol=1e-3 * np.abs(ref.stacked_basis).max())
    np.testing.assert_allclose(model.weights, ref.weights, atol=1e-4)


def test_too_small_memory_bound_is_a_clear_error(waves_npy):
    path, _ = waves_npy
    with pytest.raises(ValueError, match=r"max_memory 0\.10 GiB is too small for waves\.npy .* needs at least"):
        learn_lds(spill_clip(path), n=8, max_memory=100 << 20)


def test_truncated_npy_is_a_clip_error(waves_npy, tmp_path):
    path, _ = waves_npy
    bad = tmp_path / "cut.npy"
    bad.write_bytes(path.read_bytes()[:5000])
    with pytest.raises(ClipError, match="truncated"):
        spill_clip(bad)


@pytest.mark.parametrize("text,value", [("2GB", 2 << 30), ("1.5g", 3 << 29), ("512MiB", 512 << 20), ("4096", 4096)])
def test_parse_bytes(text, value):
    assert parse_bytes(text) == value


@pytest.mark.parametrize("text", ["", "two GB", "-1GB", "3PB", "0"])
def test_parse_bytes_refuses(text):
    with pytest.raises(ValueError, match="memory size"):
        parse_bytes(text)


def test_a_streamed_clip_is_learned_on_its_levels(waves_npy):
    """Out of core there is no tone map: "auto" learns on levels, "on" is refused in one line."""
    path, _ = waves_npy
    assert learn_lds(spill_clip(path), n=4).tone is None
    with pytest.raises(InvalidArgumentError, match="tone='on' needs the clip in memory"):
        learn_lds(spill_clip(path), n=4, tone="on")
    with pytest.raises(InvalidArgumentError, match="tone='on' needs the clip in memory"):
        learn_mixture(spill_clip(path), components=2, dim=3, pca_dim=8, neighbors=8, pmax=2, tone="on")
