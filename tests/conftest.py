"""Fixtures shared by the whole suite: real clips, generated clips, temporary databases,
and the OpenCL devices the kernel tests run on.

Before anything imports pyopencl, this file (1) points the self-test's verdict cache at a
folder of this session (unless ``DYNATEX_CACHE_DIR`` names one), so every run proves its
devices afresh and leaves the user's cache alone, and (2) where the test extra installed
Intel's CPU OpenCL runtime, makes it visible beside the system's OpenCL platforms (its own
ICD file names a path that does not exist), so that the kernels are compared with their
references on two independent compilers. Set ``OCL_ICD_VENDORS`` yourself to choose the platforms instead.
"""

from __future__ import annotations

import atexit
import os
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest

CLIPS = Path(__file__).resolve().parents[2] / "shared" / "data" / "clips"
SYSTEM_VENDORS = Path("/etc/OpenCL/vendors")


def _session_folder(prefix: str) -> Path:
    folder = Path(tempfile.mkdtemp(prefix=prefix))
    atexit.register(shutil.rmtree, folder, True)
    return folder


def _add_intel_runtime() -> None:
    """Make Intel's CPU runtime (pip package intel-opencl-rt) visible, if installed."""
    lib = Path(sys.prefix) / "lib" / "libintelocl.so"
    if "OCL_ICD_VENDORS" in os.environ or not lib.is_file():
        return
    vendors = _session_folder("dynatex-icd-")
    if SYSTEM_VENDORS.is_dir():
        for icd in SYSTEM_VENDORS.glob("*.icd"):
            shutil.copy(icd, vendors)
    (vendors / "intel-cpu-dynatex-tests.icd").write_text(f"{lib}\n")
    os.environ["OCL_ICD_VENDORS"] = str(vendors)


os.environ.setdefault("DYNATEX_CACHE_DIR", str(_session_folder("dynatex-cache-")))
_add_intel_runtime()


def verified_devices() -> list:
    """The OpenCL devices that passed the self-test here, in the player's order of preference."""
    from dynatex.player.opencl import context as opencl
    from dynatex.player.opencl import verify

    try:
        infos = opencl.preference_order(opencl.devices())
    except opencl.OpenCLUnavailableError:
        return []
    return [d for d in infos if verify.verdict(d).ok]


def opencl_backends() -> list[str]:
    """``["numpy", "opencl"]`` where an OpenCL device passed the self-test here, else ``["numpy"]``:
    a test comparing the backends runs on the broken-driver machines too, on what they have."""
    return ["numpy", "opencl"] if verified_devices() else ["numpy"]


def best_backend() -> str:
    """``"opencl"`` where a device passed the self-test here, else ``"numpy"`` (no fallback warning)."""
    return opencl_backends()[-1]


def pytest_generate_tests(metafunc):
    """Kernel tests (fixture ``cl_device`` or ``cl_context``) run once on every verified device."""
    if "cl_device" in metafunc.fixturenames:
        devices = verified_devices()
        ids = [f"{d.index}-{d.platform.split()[0]}" for d in devices]
        metafunc.parametrize(
            "cl_device",
            [d.index for d in devices]
            or [pytest.param(None, marks=pytest.mark.skip(reason="no verified OpenCL device"))],
            ids=ids or None,
            scope="session",
        )


@pytest.fixture(scope="session")
def clips_dir() -> Path:
    """``../shared/data/clips`` beside the checkout; tests using it skip when it is absent."""
    if not CLIPS.is_dir():
        pytest.skip(f"real clips not available: {CLIPS} does not exist (they live beside the checkout)")
    return CLIPS


@pytest.fixture(scope="session")
def cl_context(cl_device):
    """The shared OpenCL context of device ``cl_device`` (one verified device per parameter)."""
    from dynatex.player.opencl.context import get_context

    return get_context(cl_device)


def wave_clip(
    t: int = 60,
    h: int = 24,
    w: int = 32,
    *,
    channels: int = 3,
    seed: int = 0,
    periods: tuple[float, ...] = (17.0, 11.0),
) -> np.ndarray:
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
        frames = np.concatenate([frames, np.clip(frames * 0.8 + 20, 0, 255).astype(np.uint8), 255 - frames], axis=3)
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
