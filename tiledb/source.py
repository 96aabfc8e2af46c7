"""Description of the clip a texture was learned from (the ``source`` group)."""

from __future__ import annotations

from dataclasses import dataclass, field

import h5py

from ._check import Checker


@dataclass(frozen=True)
class SourceInfo:
    """Where a texture came from and the pixel layout every method of it uses.

    Frames are ``(height, width, channels)`` uint8, ``channels`` 3 (RGB) or 1 (grey).
    """

    filename: str
    sha256: str
    fps: float
    width: int
    height: int
    channels: int
    n_frames: int
    frame_start: int = 0
    frame_step: int = 1
    crop: tuple[int, ...] = ()  # (x, y, w, h) in source pixels, () when uncropped: a rectangle, as --crop X,Y,W,H
    source_size: tuple[int, ...] = ()  # (height, width) of the decoded source frames; the file stores (w, h)
    extra: dict = field(default_factory=dict, compare=False)

    @property
    def color_order(self) -> str:
        return "RGB" if self.channels == 3 else "GRAY"

    @property
    def frame_shape(self) -> tuple[int, int, int]:
        return (self.height, self.width, self.channels)

    @property
    def pixels(self) -> int:
        """Values per frame: ``height * width * channels``."""
        return self.height * self.width * self.channels


def write(group: h5py.Group, info: SourceInfo) -> None:
    a = group.attrs
    a["filename"] = info.filename
    a["sha256"] = info.sha256
    a["fps"] = float(info.fps)
    a["width"] = int(info.width)
    a["height"] = int(info.height)
    a["channels"] = int(info.channels)
    a["color_order"] = info.color_order
    a["n_frames"] = int(info.n_frames)
    a["frame_start"] = int(info.frame_start)
    a["frame_step"] = int(info.frame_step)
    a["crop"] = [int(v) for v in info.crop] if info.crop else [-1, -1, -1, -1]
    a["source_size"] = [int(v) for v in info.source_size[::-1]] if info.source_size else [-1, -1]  # file: (w, h)


def read(group: h5py.Group, check: Checker) -> SourceInfo:
    att = check.attr
    width, height = att(group, "width", int), att(group, "height", int)
    channels, n_frames = att(group, "channels", int), att(group, "n_frames", int)
    fps = att(group, "fps", float)
    if not (0 < width <= 65536 and 0 < height <= 65536):
        check.fail(group.name, f"implausible frame size {width}x{height}")
    if channels not in (1, 3):
        check.fail(group.name + "@channels", f"must be 1 or 3, not {channels}")
    if n_frames < 2:
        check.fail(group.name + "@n_frames", f"must be at least 2, not {n_frames}")
    if not fps > 0:
        check.fail(group.name + "@fps", f"must be positive, not {fps}")
    order = att(group, "color_order", str)
    if order != ("RGB" if channels == 3 else "GRAY"):
        check.fail(group.name + "@color_order", f"{order!r} does not match {channels} channels")
    crop = check.ints(group, "crop", 4, (-1, -1, -1, -1))
    size = check.ints(group, "source_size", 2, (-1, -1))
    if min(crop) < 0 and max(crop) != -1 or min(crop) >= 0 and (crop[2] < 1 or crop[3] < 1):
        check.fail(
            group.name + "@crop", f"{crop} is neither (x, y, w, h) with x, y >= 0 and w, h >= 1 nor (-1, -1, -1, -1)"
        )
    if min(size) < 0 and max(size) != -1 or min(size) == 0:
        check.fail(group.name + "@source_size", f"{size} is neither (w, h) with w, h >= 1 nor (-1, -1)")
    return SourceInfo(
        filename=att(group, "filename", str),
        sha256=att(group, "sha256", str),
        fps=fps,
        width=width,
        height=height,
        channels=channels,
        n_frames=n_frames,
        frame_start=att(group, "frame_start", int, 0),
        frame_step=att(group, "frame_step", int, 1),
        crop=() if min(crop) < 0 else crop,
        source_size=() if min(size) < 0 else size[::-1],
    )
