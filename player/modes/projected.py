"""What the projection modes (``lds``, ``mixture``) share: a player whose frame is the
projection of a small vector, advanced on the host once per frame, through a stored basis.

A model with a ``detail`` part (:mod:`dynatex.tiledb.detail`) also opens the detail engine
(:mod:`dynatex.player.engines.detail`), which adds the fine detail the projection lacks to each
projected frame and holds every pixel to the source's colour range.

A mode subclasses :class:`ProjectionPlayer` and supplies its model (``_setup``), the
vector it advances (``_vector``, ``_dim``, ``_step``) and how that vector becomes
projection coefficients (``_coefficients``). The base opens the projection engine
(:mod:`dynatex.player.engines.projection`), warms it, and provides ``precision``, the
``intensity`` control, ``bytes_per_frame``, ``advance`` and the frame paths.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ...checks import Choice, Range, check_int
from ...errors import InvalidArgumentError
from ...params import Param
from ..base import Player
from ..controls import Control
from ..engines import open_engine
from ..engines.detail import open_detail

PRECISIONS = ("float32", "float16")
MAX_INTENSITY = 100.0
MAX_DETAIL = 4.0


class ProjectionPlayer(Player):
    """Base of the modes whose frames are ``Projector`` projections of a host-side vector.

    Subclasses set ``mode`` and ``basis_name`` (the model's basis attribute) and implement
    ``_setup(model)`` (everything but the projector; it must set ``_shape`` and ``_dim``),
    ``_vector()`` (the vector of the next frame), ``_dim`` (its length), ``_step()``
    (advance it once) and ``_coefficients(v, coef)`` (write the coefficients for ``v``).
    """

    basis_name = "basis"
    options = (
        Param(
            "precision",
            Choice(*PRECISIONS),
            "float32",
            "Storage of the basis on the device; float16 halves the bytes each frame reads (faster, "
            "memory-bound) at PSNR above 45 dB against float32.",
        ),
    )

    checked_first = ("precision",)

    def _open(self, *, seed: int, precision: str) -> None:
        self._prefer_faster(*self._asked, f"projection {precision}")
        model = self.texture.read(self.method)
        self.model_info = dict(model.info)
        self.precision = precision
        self._setup(model)
        basis = getattr(model, self.basis_name)
        if precision == "float16":
            basis = basis.astype(np.float16)
        self.engine = open_engine(
            "projection",
            basis,
            model.mean,
            shape=self._shape,
            channels=self.texture.source.channels,
            ctx=self.ctx,
            queue=self.queue,
            format=self.format,
        )
        self.basis_bytes = self.engine.basis_bytes
        self.detail_engine = None
        self._detail_clock = 0.0
        if model.detail is not None:
            self.detail_engine = open_detail(
                model.detail,
                shape=self._shape,
                channels=self.texture.source.channels,
                src=self.engine.out.buffer if self.ctx is not None else None,
                ctx=self.ctx,
                queue=self.queue,
                format=self.format,
            )
        self.reseed(seed)
        self._project(self._vector(), np.empty(self._shape, np.uint8))  # warm the kernel

    # -- what a mode supplies ----------------------------------------------------------
    _dim: int

    def _setup(self, model) -> None:
        raise NotImplementedError

    def _vector(self) -> np.ndarray:
        raise NotImplementedError

    def _step(self) -> None:
        raise NotImplementedError

    def _coefficients(self, v: np.ndarray, coef: np.ndarray) -> None:
        raise NotImplementedError

    def _detail_rate(self) -> float:
        """Volume frames the detail advances per played frame: it keeps the model's pace."""
        return 1.0

    def _detail_state(self) -> dict[str, Any]:
        return {"detail_clock": self._detail_clock}

    def _restore_detail(self, state: dict[str, Any]) -> None:
        """The detail's clock from ``state`` (a state without one: the frame index, as it was)."""
        clock = float(state.get("detail_clock", state.get("frame_index", 0)))
        if not np.isfinite(clock):
            raise InvalidArgumentError("state detail_clock must be a finite number")
        self._detail_clock = clock

    # -- controls ----------------------------------------------------------------
    @property
    def bytes_per_frame(self) -> int:
        """The basis and mean read, plus the uint8 frame written (and the detail's reads)."""
        extra = 0 if self.detail_engine is None else self.detail_engine.bytes_per_frame
        return self.engine.bytes_per_frame + extra

    intensity = Control(
        Range(float, 0.0, MAX_INTENSITY),
        1.0,
        "Scale of the driving noise's covariance (0 follows the deterministic prediction).",
    )

    detail = Control(
        Range(float, 0.0, MAX_DETAIL),
        1.0,
        "Scale of the fine detail added to each frame (the part of the clip the projection drops; "
        "0: none, the source's colour range still holds), times sqrt(intensity); no effect on "
        "textures analysed without it.",
    )

    # -- synthesis -----------------------------------------------------------------
    def advance(self, steps: int = 1, *, record: bool = False) -> np.ndarray | None:
        """Run the recursion ``steps`` times without projecting frames.

        With ``record=True`` returns the visited vectors, ``(steps, dim)``.
        """
        steps = check_int("steps", steps, 0)
        rec = np.empty((steps, self._dim)) if record else None
        for i in range(steps):
            self._step()
            self._detail_clock += self._detail_rate()
            if rec is not None:
                rec[i] = self._vector()
        self.frame_index += steps
        return rec

    def _start(self, out: np.ndarray):
        self._coefficients(self._vector(), self.engine.coef)
        event = self._run(out, wait=False)
        self._step()
        self._detail_clock += self._detail_rate()
        return event

    def _run(self, out: np.ndarray, *, wait: bool = True):
        """Project the engine's coefficients into ``out``, adding the detail where the model has it."""
        if self.detail_engine is None:
            return self.engine.draw(out, wait=wait)
        clock = math.floor(self._detail_clock)
        layers = self.detail_engine.layers(self.seed, clock, self._detail * np.sqrt(self._intensity))
        if self.ctx is None:
            self.engine.draw(out)
            self.detail_engine.apply(out, layers)
            return None
        self.engine.run_on_device()
        return self.detail_engine.run(layers, out, wait=wait)

    def _render_vector(self, name: str, v: np.ndarray, out: np.ndarray | None) -> np.ndarray:
        """Project an arbitrary vector (checked, named ``name`` in errors); the player does not advance."""
        v = np.asarray(v, dtype=float)
        if v.shape != (self._dim,) or not np.isfinite(v).all():
            raise InvalidArgumentError(f"{name} must be a finite vector of shape ({self._dim},)")
        if out is None:
            out = np.empty(self._shape, np.uint8)
        self._project(v, out)
        return out

    def _project(self, v: np.ndarray, out: np.ndarray) -> None:
        self._coefficients(v, self.engine.coef)
        self._run(out)

    def close(self) -> None:
        """Finish the frames in flight and release the engines and the database."""
        if self.queue is not None:
            self.queue.finish()
        if getattr(self, "detail_engine", None) is not None:
            self.detail_engine.close()
            self.detail_engine = None
        super().close()
