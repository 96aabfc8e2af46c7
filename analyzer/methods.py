"""The analysis methods by name: what ``dynatex analyze --methods`` can run.

Each entry names a function ``learn(clip, *, progress=None, **params) -> model`` whose
model the tile database stores under the method's group, and whether the method plays
from the stored source frames.
"""
from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import Any, Callable


@dataclass(frozen=True)
class Method:
    name: str
    target: str              # "module:function" inside dynatex.analyzer
    needs_frames: bool       # store the clip's frames beside the model
    summary: str

    def function(self) -> Callable[..., Any]:
        module, func = self.target.split(":")
        return getattr(importlib.import_module(f"dynatex.analyzer.{module}"), func)


METHODS: dict[str, Method] = {
    "lds": Method("lds", "lds:learn_lds", False, "linear dynamic texture (Doretto & Soatto)"),
    "turnpoints": Method("turnpoints", "turnpoints:learn_turnpoints", True, "video texture with turn points and transitions (Van Haevre; Schoedl)"),
    "mixture": Method("mixture", "mixture:learn_mixture", False, "subspace mixture + global coordination + AR(p) (Liu, Lin & Ahuja)"),
    "tiles": Method("tiles", "tiles:learn_tiles", False, "triple toroid-shaped tiles, mixing and tone (Richtr & Haindl)"),
    "quilt": Method("quilt", "quilt:learn_quilt", True, "time-varying texture: SVD-accelerated quilting of spatio-temporal cuboids"),
}


def get_method(name: str) -> Method:
    if name not in METHODS:
        raise ValueError(f"method must be one of {sorted(METHODS)}, not {name!r}")
    return METHODS[name]
