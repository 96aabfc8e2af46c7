"""Fixtures and helpers shared by the storage tests: a small database with both projection models,
and damaged copies of a database."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np
import pytest

from ..conftest import wave_clip


@dataclass
class ProjectionDB:
    """A database of texture ``w`` with an ``lds`` and a ``mixture`` model of ``frames``."""

    path: Path
    models: dict
    frames: np.ndarray

    def read(self, method: str):
        """The ``method`` model as read back from :attr:`path`."""
        from dynatex.tiledb import TileDB

        with TileDB(self.path) as t:
            return t.texture("w").read(method)


@pytest.fixture(scope="session")
def projection_db(tmp_path_factory) -> ProjectionDB:
    from dynatex.analyzer import load_clip
    from dynatex.analyzer.lds import learn_lds
    from dynatex.analyzer.mixture import learn_mixture
    from dynatex.tiledb import DatabaseWriter

    clip = load_clip(wave_clip(60, h=20, w=28))
    path = tmp_path_factory.mktemp("projection") / "p.h5"
    lds = learn_lds(clip, n=5)
    mix = learn_mixture(clip, components=2, dim=3, pca_dim=12, neighbors=6, pmax=3)
    with DatabaseWriter(path) as w:
        w.put_texture("w", clip.source_info())
        w.put_method("w", "lds", lds)
        w.put_method("w", "mixture", mix)
    return ProjectionDB(path, {"lds": lds, "mixture": mix}, clip.frames)


def edited_copy(src: Path, tmp_path: Path, group: str, edit: Callable[[h5py.Group], None]) -> Path:
    """A copy of database ``src`` in ``tmp_path`` with ``edit`` applied to its group ``group``."""
    path = tmp_path / "edited.h5"
    path.write_bytes(src.read_bytes())
    with h5py.File(path, "r+") as f:
        edit(f[group])
    return path


def replace_dataset(name: str, fn: Callable[[np.ndarray], np.ndarray]) -> Callable[[h5py.Group], None]:
    """An edit that replaces dataset ``name`` (a path below the group) by ``fn`` of its data."""

    def edit(g: h5py.Group) -> None:
        data = fn(g[name][()])
        del g[name]
        g.create_dataset(name, data=data)

    return edit
