"""Fixtures shared by the whole suite: real clips, generated clips, temporary databases,
one OpenCL context for the session."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

CLIPS = Path(__file__).resolve().parents[2] / "shared" / "data" / "clips"


@pytest.fixture(scope="session")
def clips_dir() -> Path:
    """``../shared/data/clips`` beside the checkout; tests using it skip when it is absent."""
    if not CLIPS.is_dir():
        pytest.skip(f"real clips not available: {CLIPS} does not exist (they live beside the checkout)")
    return CLIPS


@pytest.fixture(scope="session")
def cl_context():
    """The session-wide OpenCL context the players use by default."""
    from dynatex.player.opencl import get_context
    return get_context()


def wave_clip(t: int = 60, h: int = 24, w: int = 32, *, channels: int = 3, seed: int = 0,
              periods: tuple[float, ...] = (17.0, 11.0)) -> np.ndarray:
    """A small synthetic dynamic texture: travelling sine waves plus a little noise, uint8."""
    rng = np.random.default_rng(seed)
    tt = np.arange(t)[:, None, None]
    yy = np.arange(h)[None, :, None]
    xx = np.arange(w)[None, None, :]
    img = np.zeros((t, h, w))
    for i, period in enumerate(periods):
        kx, ky = rng.uniform(0.1, 0.5, 2)
        img += np.sin(2 * np.pi * tt / period + kx * xx + ky * yy + i)
    img = 128 + 50 * img / len(periods) + rng.normal(0, 2, img.shape)
    frames = np.clip(img, 0, 255).astype(np.uint8)[..., None]
    if channels == 3:
        frames = np.concatenate([frames, np.clip(frames * 0.8 + 20, 0, 255).astype(np.uint8),
                                 255 - frames], axis=3)
    return frames


@pytest.fixture
def synthetic_clip() -> np.ndarray:
    return wave_clip()


@pytest.fixture
def lds_db(tmp_path, synthetic_clip):
    """A temporary database holding texture 'waves' with an LDS of the synthetic clip."""
    from dynatex.analyzer import load_clip
    from dynatex.analyzer.lds import learn_lds
    from dynatex.tiledb import DatabaseWriter
    clip = load_clip(synthetic_clip)
    path = tmp_path / "waves.h5"
    with DatabaseWriter(path) as w:
        w.put_texture("waves", clip.source_info())
        w.put_method("waves", "lds", learn_lds(clip, n=12))
    return path
