"""Mode ``lds``: real-time synthesis and live editing of a linear dynamic texture.

Per frame the host advances the n-dimensional state (``x <- A_s x + sqrt(intensity) B v``,
microseconds) and one OpenCL kernel projects it, ``frame = basis^T (w * x) + mean``,
straight to uint8: the only per-frame cost that grows with the frame size, memory-bound
on the basis.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from ..tiledb import LDSModel
from .base import check_float, rng_from_state
from .projected import ProjectionPlayer

MAX_WEIGHT = 10.0
SPEED_RANGE = (-3.0, 3.0)


def scale_groups(n: int) -> np.ndarray:
    """Group of each component: 0 coarse, 1 medium, 2 fine (the seed's 5/10/35 split of n=50)."""
    c = max(1, int(round(0.1 * n)))
    m = max(c + 1, int(round(0.3 * n))) if n > 2 else min(n, c + 1)
    groups = np.full(n, 2, np.int8)
    groups[:m] = 1
    groups[:c] = 0
    return groups


def edited_poles(poles: np.ndarray, speed: float) -> np.ndarray:
    """Poles for playback at ``speed``: angles scaled by ``speed`` (negative reverses time),
    magnitudes kept; poles pushed past pi are annihilated (set to 0).

    Real negative poles (angle pi) have no conjugate partner to rotate with; they become
    ``|p| cos(speed * pi)``, the real part of the rotated pole.
    """
    mag = np.abs(poles)
    ang = np.angle(poles)
    neg_real = (np.abs(poles.imag) <= 1e-12 * np.maximum(mag, 1e-300)) & (poles.real < 0)
    new = mag * np.exp(1j * ang * speed)
    new = np.where(neg_real, mag * np.cos(np.pi * speed), new)
    new = np.where(np.abs(ang * speed) > np.pi + 1e-12, 0.0, new)
    return new


class LDSPlayer(ProjectionPlayer):
    """Endless frames from a texture's ``lds`` model, with live edits.

    Parameters
    ----------
    db : path or TileDB
        The tile database.
    texture : str, optional
        Texture name (optional when the database holds one texture).
    backend : {"auto", "opencl", "numpy"}
        See :class:`~dynatex.player.base.Player`.
    device : str, optional
        OpenCL device (see :func:`dynatex.player.opencl.get_context`).
    format : {"RGB", "RGBA", "BGRA"}
        Pixel format of the frames (see :class:`~dynatex.player.base.Player`).
    seed : int
        Seed of the driving noise; the same seed gives the same frames.
    precision : {"float32", "float16"}
        Storage of the basis on the device. ``"float16"`` halves the bytes each frame
        reads (faster, memory-bound) at PSNR above 45 dB against float32.

    Controls (attributes, changeable between any two frames)
    ---------------------------------------------------------
    speed : float in [-3, 3]
        Pole angles scaled by ``speed``; negative plays time backwards.
    intensity : float >= 0
        Scale of the driving noise covariance ``Q`` (0 lets the texture settle to the mean).
    scales : (coarse, medium, fine), each in [0, 10]
        Weights of the three groups of components.
    weights : (n,) array, each in [0, 10]
        Per-component weights, multiplied with ``scales``.

    Examples
    --------
    >>> with LDSPlayer("water.h5", seed=3) as p:     # doctest: +SKIP
    ...     p.speed = -1.0                            # play backwards
    ...     frame = p.next_frame()
    """

    mode = "lds"

    def _setup(self, model: LDSModel) -> None:
        src = self.texture.source
        self.n, self.k = model.n, model.k
        self._dim = self.n
        self._shape = (src.height, src.width, self.format.bytes)
        self._A = model.A.copy()
        self._B = model.B.copy()
        self._x0 = model.x0.copy()
        self.stationary_cov = model.stationary_cov
        self._poles, self._vecs = np.linalg.eig(self._A)
        self._vecs_inv = np.linalg.inv(self._vecs)
        self._groups = scale_groups(self.n)
        self._speed = 1.0
        self._scales = np.ones(3)
        self._weights = np.ones(self.n)
        self._A_edit = self._A
        self._w = np.ones(self.n)
        self._x = self._x0.copy()

    # -- controls ----------------------------------------------------------------
    @property
    def speed(self) -> float:
        return self._speed

    @speed.setter
    def speed(self, value: float) -> None:
        self._speed = check_float("speed", value, *SPEED_RANGE)
        if self._speed == 1.0:
            self._A_edit = self._A
        else:
            poles = edited_poles(self._poles, self._speed)
            self._A_edit = np.ascontiguousarray(((self._vecs * poles) @ self._vecs_inv).real)

    @property
    def scales(self) -> tuple[float, float, float]:
        return tuple(float(v) for v in self._scales)  # type: ignore[return-value]

    @scales.setter
    def scales(self, value) -> None:
        vals = np.asarray(value, dtype=float) if not isinstance(value, str) else None
        if vals is None or vals.shape != (3,):
            raise ValueError(f"scales must be three numbers (coarse, medium, fine), not {value!r}")
        self._scales = np.array([check_float(f"scales[{i}]", v, 0.0, MAX_WEIGHT) for i, v in enumerate(vals)])
        self._update_w()

    @property
    def weights(self) -> np.ndarray:
        return self._weights.copy()

    @weights.setter
    def weights(self, value) -> None:
        vals = np.asarray(value, dtype=float)
        if vals.shape != (self.n,):
            raise ValueError(f"weights must have shape ({self.n},), not {vals.shape}")
        if not np.isfinite(vals).all() or vals.min() < 0 or vals.max() > MAX_WEIGHT:
            raise ValueError(f"weights must be finite and within [0, {MAX_WEIGHT}]")
        self._weights = vals.copy()
        self._update_w()

    def _update_w(self) -> None:
        self._w = self._scales[self._groups] * self._weights

    @property
    def groups(self) -> np.ndarray:
        """Scale group of each component (0 coarse, 1 medium, 2 fine)."""
        return self._groups.copy()

    # -- synthesis -----------------------------------------------------------------
    @property
    def state(self) -> np.ndarray:
        """The current state vector ``x`` (a copy)."""
        return self._x.copy()

    def _step(self) -> None:
        v = self._rng.standard_normal(self.k)
        self._x = self._A_edit @ self._x + np.sqrt(self._intensity) * (self._B @ v)

    def _vector(self) -> np.ndarray:
        return self._x

    def _coefficients(self, x: np.ndarray, coef: np.ndarray) -> None:
        np.multiply(self._w, x, out=coef[: self.n], casting="same_kind")

    def render_state(self, x: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """Project an arbitrary state to a frame (the current weights apply); the player does not advance."""
        return self._render_vector("x", x, out)

    # -- state ---------------------------------------------------------------------
    def _get_state(self) -> dict[str, Any]:
        return {"x": self._x.copy(), "rng": self._rng.bit_generator.state, "seed": self.seed,
                "speed": self._speed, "intensity": self._intensity, "scales": self._scales.copy(),
                "weights": self._weights.copy()}

    def _set_state(self, state: dict[str, Any]) -> None:
        x = np.asarray(state["x"], dtype=float)
        if x.shape != (self.n,) or not np.isfinite(x).all():
            raise ValueError(f"state x must be finite with shape ({self.n},)")
        rng = rng_from_state(state["rng"])
        self.speed = state["speed"]
        self.intensity = state["intensity"]
        self.scales = state["scales"]
        self.weights = state["weights"]
        self._x = x.copy()
        self._rng = rng
        self.seed = int(state.get("seed", self.seed))
