"""Rebuild ``player/selftest.h5``, the small database the device self-test plays.

    python tools/make_selftest_db.py

Every method on one generated 48-frame 32x24 clip: a smooth random texture swinging
sideways (a period of 16 frames, so turn points exist), small enough to ship (~0.8 MB)
and to check a device in seconds. Run it after a format change; the self-test's cached
verdicts follow the file's content.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np

from dynatex.analyzer import load_clip
from dynatex.analyzer.lds import learn_lds
from dynatex.analyzer.mixture import learn_mixture
from dynatex.analyzer.quilt import learn_quilt
from dynatex.analyzer.tiles import learn_tiles
from dynatex.analyzer.turnpoints import learn_turnpoints
from dynatex.player.opencl.selftest import TEXTURE
from dynatex.tiledb import DatabaseWriter

OUT = Path(__file__).resolve().parents[1] / "player" / "selftest.h5"


def swinging_clip(t: int = 48, h: int = 24, w: int = 32, seed: int = 0) -> np.ndarray:
    """``(t, h, w, 3)`` uint8: a smooth random texture moved sideways by 12 sin(2 pi t / 16) px."""
    rng = np.random.default_rng(seed)
    noise = rng.normal(size=(h, 2 * w, 3))
    fy, fx = np.fft.fftfreq(h)[:, None], np.fft.fftfreq(2 * w)[None, :]
    low = np.exp(-(fy**2 + fx**2) * 300)
    tex = np.stack([np.real(np.fft.ifft2(np.fft.fft2(noise[..., c]) * low)) for c in range(3)], -1)
    tex = (tex - tex.mean()) / tex.std() * 40 + 128
    frames = [tex[:, int(round(16 + 12 * np.sin(2 * np.pi * k / 16))) :][:, :w] for k in range(t)]
    return np.clip(np.array(frames), 0, 255).astype(np.uint8)


def main() -> int:
    clip = load_clip(swinging_clip())
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "selftest.h5"
        with DatabaseWriter(path) as db:
            db.put_texture(TEXTURE, clip.source_info())
            db.put_frames(TEXTURE, clip.frames)
            db.put_method(TEXTURE, "lds", learn_lds(clip, n=6))
            db.put_method(TEXTURE, "turnpoints", learn_turnpoints(clip))
            db.put_method(TEXTURE, "tiles", learn_tiles(clip, tile=16, construction="ring"))
            db.put_method(TEXTURE, "quilt", learn_quilt(clip, size=(48, 64), block=12))
            db.put_method(TEXTURE, "mixture", learn_mixture(clip))
        OUT.write_bytes(path.read_bytes())
    print(f"wrote {OUT} ({OUT.stat().st_size / 1e6:.2f} MB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
