"""The engines that draw the modes' frames, one module each, and the interface they share.

A mode holds one :class:`Engine` in ``player.engine``: :mod:`.projection` (lds, mixture),
:mod:`.gather` (tiles), :mod:`.stochastic` (tiles above the torus's size), :mod:`.runs`
(evolve) or :mod:`.blend` (turnpoints, with :mod:`.warp` for motion-compensated jumps); the
projection engine adds a model's fine detail (:mod:`.detail`) in the same pass. Each is a pair
of an OpenCL engine and its numpy reference computing the same integers, opened by
:func:`open_engine`; each OpenCL engine draws with the kernel of its name
(``kernels/projection.cl``, ``kernels/gather.cl``, ``kernels/stochastic.cl``,
``kernels/runs.cl``, ``kernels/blend.cl``, ``kernels/warp.cl``). :mod:`.base` holds what the
OpenCL engines share.

Examples
--------
>>> import numpy as np
>>> frames = np.zeros((2, 4, 6, 3), np.uint8)
>>> frames[1] = 200
>>> engine = open_engine("blend", frames)                      # no ctx: the numpy reference
>>> isinstance(engine, Engine), engine.backend
(True, 'numpy')
>>> out = np.empty(engine.shape, np.uint8)
>>> engine.draw(out, ((0, 128), (1, 128)))                      # the frame is in out
>>> int(out[0, 0, 0])
100
"""

from __future__ import annotations

import importlib
from typing import Any, Protocol, runtime_checkable

import numpy as np

from ...errors import InvalidArgumentError

#: the backends of every engine: its OpenCL engine, or its numpy reference
BACKENDS = ("opencl", "numpy")

#: engine -> (module of this package, numpy reference class, OpenCL class)
ENGINES: dict[str, tuple[str, str, str]] = {
    "projection": ("projection", "ProjectorReference", "ProjectorOpenCL"),
    "gather": ("gather", "GatherReference", "GatherOpenCL"),
    "runs": ("runs", "RunsReference", "RunsOpenCL"),
    "blend": ("blend", "BlendReference", "BlendOpenCL"),
    "stochastic": ("stochastic", "StochasticReference", "StochasticOpenCL"),
}


@runtime_checkable
class Engine(Protocol):
    """What a mode's engine is: built from the model's arrays (uploaded once), it draws a frame
    into the caller's array and releases its device memory on :meth:`close`."""

    #: "opencl" or "numpy" (:data:`BACKENDS`)
    backend: str

    @property
    def bytes_per_frame(self) -> int:
        """Bytes of memory a frame moves at least (for roofline figures)."""
        ...

    def draw(self, out: np.ndarray, *frame: Any, wait: bool = True, **options: Any) -> Any:
        """Draw the frame that ``frame`` (and ``options``) describe into ``out``; return None once
        ``out`` holds it, or with ``wait=False`` the OpenCL event after which it does, so a mode
        can keep a frame in flight."""
        ...

    def close(self) -> None:
        """Release what the engine holds on a device (nothing for a reference)."""
        ...


def open_engine(kind: str, *model: Any, ctx: Any = None, queue: Any = None, **options: Any) -> Engine:
    """Engine ``kind`` (:data:`ENGINES`) built from ``model`` and ``options``: its OpenCL engine
    on ``ctx``/``queue``, or its numpy reference when ``ctx`` is None. Every mode chooses the
    backend this way (the player picked ``ctx``, or None for numpy, when it opened)."""
    if kind not in ENGINES:
        raise InvalidArgumentError(f"engine must be one of {', '.join(ENGINES)}, not {kind!r}")
    module, reference, opencl = ENGINES[kind]
    classes = importlib.import_module(f"{__name__}.{module}")
    if ctx is None:
        return getattr(classes, reference)(*model, **options)
    return getattr(classes, opencl)(*model, ctx=ctx, queue=queue, **options)


__all__ = ["BACKENDS", "ENGINES", "Engine", "open_engine"]
