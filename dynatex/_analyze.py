"""``dynatex.analyze``: what ``dynatex analyze CLIP -o DB`` does, as one call from Python."""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import Any

import numpy as np

from .errors import InvalidArgumentError


def analyze(
    clip: str | os.PathLike | np.ndarray,
    db: str | os.PathLike,
    *,
    name: str | None = None,
    methods: Sequence[str] = ("lds",),
    params: dict[str, dict[str, Any]] | None = None,
    **load: Any,
) -> str:
    """Learn ``methods`` from ``clip`` and write them as texture ``name`` into database ``db``.

    Other textures of ``db`` are kept, and the write is atomic (a temporary file, then a rename).

    Parameters
    ----------
    clip : str, os.PathLike or numpy.ndarray
        A video file, a folder of images, a ``.npy`` array, or frames ``(T, H, W[, 3])`` uint8.
    db : str or os.PathLike
        The tile database to create or update.
    name : str, optional
        The texture's name; default the clip file's name without extension (``clip`` for an array).
    methods : sequence of str
        Analysis methods: ``lds``, ``turnpoints``, ``tiles``, ``quilt``, ``mixture``
        (``dynatex analyze --help`` lists each one's parameters).
    params : dict, optional
        Per method, keyword arguments of its learn function, e.g. ``{"lds": {"n": 30}}``.
    **load
        How to read the clip (:func:`dynatex.analyzer.load_clip`'s ``start``, ``stop``, ``step``,
        ``crop``, ``size`` as (height, width), ``color``).

    Returns
    -------
    str
        The texture's name in ``db``.

    Examples
    --------
    >>> import os, tempfile, dynatex
    >>> from dynatex.sample import ripples
    >>> folder = tempfile.mkdtemp()
    >>> db = os.path.join(folder, "textures.h5")
    >>> dynatex.analyze(ripples(40, 24, 32), db, name="ripples", params={"lds": {"n": 8}})
    'ripples'
    >>> with dynatex.open_player(db, backend="numpy") as player:
    ...     player.mode, player.next_frame().shape
    ('lds', (24, 32, 3))
    """
    from .analyzer.methods import get_method
    from .tiledb import DatabaseWriter
    from .tiledb.schema import texture_name_from_path

    params = dict(params or {})
    chosen = [get_method(m) for m in methods]
    unknown = sorted(set(params) - {m.name for m in chosen})
    if unknown:
        raise InvalidArgumentError(f"params names methods not in methods: {', '.join(unknown)}")
    if isinstance(clip, (str, os.PathLike)):
        from .analyzer.corpus import learn_into

        texture = name or texture_name_from_path(clip)
        with DatabaseWriter(db) as writer:
            learn_into(writer, texture, os.fspath(clip), [m.name for m in chosen], params=params, load=load)
        return texture
    from .analyzer import load_clip

    texture = name or "clip"
    frames = load_clip(clip, **load)
    with DatabaseWriter(db) as writer:
        writer.put_texture(texture, frames.source_info())
        if any(m.needs_frames for m in chosen):
            writer.put_frames(texture, frames.frames)
        for m in chosen:
            writer.put_method(texture, m.name, m.function()(frames, **params.get(m.name, {})))
    return texture


__all__ = ["analyze"]
