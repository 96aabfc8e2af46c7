"""Names and versions of the tile database layout, in one place.

Only the :mod:`dynatex.tiledb` package uses these; every other part of dynatex goes
through its API. ``FORMAT.md`` beside this file documents what they mean.
"""

from __future__ import annotations

import os
import unicodedata
from collections.abc import Sequence

FORMAT_NAME = "dynatex-tiledb"
#: (major, minor) of a file that holds a required part (:data:`REQUIRED_PARTS`): older readers,
#: which would play its models without the part, refuse its major.
FORMAT_VERSION = (2, 1)
#: (major, minor) of a file without a required part: every 1.x reader reads it.
COMPATIBLE_VERSION = (1, 8)
#: The major versions a reader reads; it refuses any other and accepts any minor of these.
READ_MAJORS = (1, 2)

# Root attributes.
ATTR_FORMAT = "format"
ATTR_VERSION = "format_version"
ATTR_CREATED_BY = "created_by"

# Groups.
TEXTURES = "textures"
SOURCE = "source"
FRAMES = "frames"

#: Method groups a texture may hold, in the order ``dynatex info`` lists them.
METHOD_LDS = "lds"
METHOD_TURNPOINTS = "turnpoints"
METHOD_TILES = "tiles"
METHOD_QUILT = "quilt"
METHOD_MIXTURE = "mixture"
METHODS = (METHOD_LDS, METHOD_TURNPOINTS, METHOD_TILES, METHOD_QUILT, METHOD_MIXTURE)

#: The per-channel tone map of a projection model (``tone.py``).
PART_TONE = "tone"
#: Parts of a method group that no reader may play without (their models' values mean nothing
#: without them): a file holding one is written as :data:`FORMAT_VERSION`, else as
#: :data:`COMPATIBLE_VERSION`.
REQUIRED_PARTS = {METHOD_LDS: (PART_TONE,), METHOD_MIXTURE: (PART_TONE,)}

#: Longest texture name, in characters.
MAX_TEXTURE_NAME = 64
#: What a texture name is, for messages.
TEXTURE_NAME_RULE = (
    f"1-{MAX_TEXTURE_NAME} characters in Unicode NFC, no '/', no control characters or line "
    "breaks, not starting with '.' and without spaces at either end"
)


def texture_name_problem(name: object) -> str | None:
    """What makes ``name`` no valid texture name (see :data:`TEXTURE_NAME_RULE`), or None.

    Any letter of any script is fine: the name is HDF5 link name (UTF-8) and the handle a game
    passes to the player. Refused are what would break a path (``/``, a leading ``.``: ``.``
    and ``..``), a line of output (control characters, line and paragraph separators), or a
    lookup (two spellings of one name: names are stored in NFC).
    """
    if not isinstance(name, str):
        return f"is a {type(name).__name__}, not a string"
    if not 1 <= len(name) <= MAX_TEXTURE_NAME:
        return f"has {len(name)} characters"
    if "/" in name:
        return "contains '/'"
    if name[0] == ".":
        return "starts with '.'"
    if name != name.strip():
        return "has spaces at an end"
    for ch in name:
        if unicodedata.category(ch)[0] == "C" or unicodedata.category(ch) in ("Zl", "Zp"):
            return f"contains the control or unassigned character U+{ord(ch):04X}"
    if unicodedata.normalize("NFC", name) != name:
        return "is not in Unicode NFC"
    return None


def texture_name_from(text: str) -> str:
    """A valid texture name made from ``text`` (a clip's file name without extension): NFC, characters
    a name cannot hold replaced by ``_``, leading dots and end spaces dropped, at most
    :data:`MAX_TEXTURE_NAME` characters; ``"texture"`` when nothing is left."""
    text = unicodedata.normalize("NFC", text)
    text = "".join(
        "_" if ch == "/" or unicodedata.category(ch)[0] == "C" or unicodedata.category(ch) in ("Zl", "Zp") else ch
        for ch in text
    )
    text = text.strip().lstrip(".").strip()[:MAX_TEXTURE_NAME].rstrip()
    text = unicodedata.normalize("NFC", text)  # cutting may split a character from its combining marks
    return text if texture_name_problem(text) is None else "texture"


def texture_name_from_path(path: str | os.PathLike) -> str:
    """The texture name a clip at ``path`` gets by default: its file name without extension, made
    valid by :func:`texture_name_from`.

    >>> texture_name_from_path("clips/sea wave.avi"), texture_name_from_path("clips/.x.npy")
    ('sea wave', 'x')
    """
    return texture_name_from(os.path.splitext(os.path.basename(os.path.normpath(os.fspath(path))))[0])


def texture_names_from_paths(paths: Sequence[str | os.PathLike]) -> list[str]:
    """One valid, distinct texture name per clip (:func:`texture_name_from_path`; ``_2``, ``_3``
    on clashes). Names that differ only in case clash too: a corpus also names its files by them.

    >>> texture_names_from_paths(["a/Sea.avi", "b/sea.avi", "c/über.npy"])
    ['Sea', 'sea_2', 'über']
    """
    names: list[str] = []
    taken: set[str] = set()
    for path in paths:
        base = texture_name_from_path(path)
        name, i = base, 2
        while name.casefold() in taken:
            suffix = f"_{i}"
            name, i = texture_name_from(base[: MAX_TEXTURE_NAME - len(suffix)]) + suffix, i + 1
        names.append(name)
        taken.add(name.casefold())
    return names


#: Largest dimension any stored array may declare; guards hostile files.
MAX_ELEMENTS = 2**34
#: Most groups and datasets a database may hold (a corpus of a thousand textures holds about 30,000).
MAX_OBJECTS = 100_000
