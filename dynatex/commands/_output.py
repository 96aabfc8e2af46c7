"""Writing rendered frames: a video (OpenCV's VideoWriter) or numbered PNG files.

Every way this can fail ends in one :class:`OutputError` naming the output and the reason:
a frame rate or frame size the codec refuses is refused here before OpenCV sees it (an
infinite frame rate made FFmpeg loop for ever), FFmpeg's own log lines are kept off the
terminal and the last of them becomes the reason, and a video that cannot be read back
whole after closing (disk full, a device instead of a file) is an error, not a silent loss.
"""
from __future__ import annotations

import contextlib
import math
import os
import sys
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..cli import OutputError

if TYPE_CHECKING:
    from typing_extensions import Self

#: Frame rates every container below writes and reads back: FFmpeg's MPEG-4 encoder refuses
#: a time base finer than 1/65535 and OpenCV cannot open one coarser than 1/100 s.
MIN_FPS = 0.01
MAX_FPS = 1000.0


@dataclass(frozen=True)
class VideoCodec:
    fourcc: str
    label: str
    min_side: int       # width and height the encoder accepts
    max_side: int


VIDEO_CODECS = {
    ".mp4": VideoCodec("mp4v", "MPEG-4 (mp4v)", 2, 8191),
    ".mkv": VideoCodec("XVID", "MPEG-4 (XVID)", 2, 8191),
    ".avi": VideoCodec("MJPG", "Motion JPEG", 1, 65535),
}


def check_fps(fps: float, what: str = "frame rate") -> float:
    """``fps`` as a float in ``[MIN_FPS, MAX_FPS]``, else an :class:`OutputError`."""
    try:
        v = float(fps)
    except (TypeError, ValueError):
        raise OutputError(f"{what} must be a number, not {fps!r}") from None
    if not (math.isfinite(v) and MIN_FPS <= v <= MAX_FPS):
        raise OutputError(f"{what} must be a finite number in [{MIN_FPS:g}, {MAX_FPS:g}] frames per second, "
                          f"not {fps!r}")
    return v


class FrameWriter:
    """Writes ``(H, W, 3)`` RGB uint8 frames to ``output``: ``.mp4``/``.mkv``/``.avi``, a ``.png``
    pattern (``%d`` in it, else ``NAME_00000.png``...) or a folder (``frame_00000.png``...).

    Call :meth:`open` with the frame shape and rate before the first :meth:`write`, so that a
    refusal comes before any rendering; :meth:`close` checks that the video is complete.
    """

    def __init__(self, output: str) -> None:
        self.output = output
        self.index = 0
        self._video = None
        self._codec: VideoCodec | None = None
        self._shape: tuple[int, int] | None = None
        self._log = None
        low = output.lower()
        if low.endswith(".png"):
            self.kind = "png"
            self.pattern = output if "%" in output else output[:-4] + "_%05d.png"
        elif os.path.isdir(output) or output.endswith(os.sep):
            self.kind = "png"
            self.pattern = os.path.join(output, "frame_%05d.png")
        elif os.path.splitext(low)[1] in VIDEO_CODECS:
            self.kind = "video"
            self._codec = VIDEO_CODECS[os.path.splitext(low)[1]]
        else:
            raise OutputError(f"output {output!r}: use {', '.join(VIDEO_CODECS)}, a .png pattern or a folder")
        if self.kind == "png":
            try:
                self.pattern % 0
            except (TypeError, ValueError):
                raise OutputError(f"output {output!r}: the .png pattern needs one integer field like %05d") from None
        folder = os.path.dirname(os.path.abspath(self.pattern if self.kind == "png" else output))
        if not (os.path.isdir(folder) or (self.kind == "png" and folder == os.path.abspath(output))):
            raise OutputError(f"output folder {folder} does not exist")

    def open(self, shape: tuple[int, ...], fps: float) -> None:
        """Prepare to write frames of ``shape`` (H, W[, 3]) at ``fps``; raise :class:`OutputError` if the
        output cannot take them."""
        h, w = int(shape[0]), int(shape[1])
        self._shape = (h, w)
        if self.kind == "png":
            folder = os.path.dirname(os.path.abspath(self.pattern))
            try:
                os.makedirs(folder, exist_ok=True)
            except OSError as exc:
                raise OutputError(f"cannot create output folder {folder}: {exc.strerror or exc}") from None
            return
        codec = self._codec
        assert codec is not None
        fps = check_fps(fps, f"frame rate of {self.output}")
        if not (codec.min_side <= w <= codec.max_side and codec.min_side <= h <= codec.max_side):
            fits = [f"{ext} ({c.label})" for ext, c in VIDEO_CODECS.items()
                    if c.min_side <= min(w, h) and max(w, h) <= c.max_side]
            raise OutputError(f"cannot write {w}x{h} frames to {self.output}: {codec.label} takes widths and "
                              f"heights {codec.min_side}..{codec.max_side}; use {' or '.join(fits + ['PNG frames'])}")
        existed = os.path.lexists(self.output)
        if os.path.exists(self.output) and not os.path.isfile(self.output):
            raise OutputError(f"cannot write video {self.output}: it exists and is not a regular file")
        try:        # the OS's reason, which OpenCV would swallow
            os.close(os.open(self.output, os.O_WRONLY | os.O_CREAT | getattr(os, "O_NONBLOCK", 0), 0o666))
        except OSError as exc:
            raise OutputError(f"cannot write video {self.output}: {exc.strerror or exc}") from None
        import cv2
        self._log = tempfile.TemporaryFile()  # noqa: SIM115 (kept open until close(): FFmpeg's log)
        with self._quiet("cannot open"):
            self._video = cv2.VideoWriter(self.output, cv2.VideoWriter_fourcc(*codec.fourcc), fps, (w, h))
            if not self._video.isOpened():
                self._video = None
        if self._video is None:
            if not existed and os.path.isfile(self.output) and os.path.getsize(self.output) == 0:
                os.unlink(self.output)                  # OpenCV leaves an empty file behind
            raise OutputError(f"cannot write video {self.output}: {self._reason('OpenCV refused to open it')}")

    def write(self, frame: np.ndarray) -> None:
        """Append one RGB frame (the shape given to :meth:`open`)."""
        if self._shape is None:
            raise RuntimeError("FrameWriter.open must come before write")
        if frame.shape[:2] != self._shape:
            raise ValueError(f"frame is {frame.shape[1]}x{frame.shape[0]}, the output was opened for "
                             f"{self._shape[1]}x{self._shape[0]}")
        import cv2
        bgr = cv2.cvtColor(frame, cv2.COLOR_RGB2BGR)
        if self.kind == "png":
            path = self.pattern % self.index
            ok, data = cv2.imencode(".png", bgr)
            if not ok:
                raise OutputError(f"cannot encode frame {self.index} as PNG")
            try:
                with open(path, "wb") as f:
                    f.write(data.tobytes())
            except OSError as exc:
                raise OutputError(f"cannot write {path}: {exc.strerror or exc}") from None
        else:
            if self._video is None:
                raise OutputError(f"video {self.output} is not open")
            with self._quiet("cannot write"):
                self._video.write(bgr)
        self.index += 1

    def close(self) -> None:
        """Finish the video and check that it reads back with every frame written."""
        if self._video is None:
            return
        import cv2
        video, self._video = self._video, None
        try:
            with self._quiet("cannot finish"):
                video.release()
                cap = cv2.VideoCapture(self.output)
                count = int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) if cap.isOpened() else 0
                cap.release()
            if count < self.index:
                raise OutputError(f"video {self.output} is incomplete: {count} of {self.index} frames read back "
                                  f"(disk full, or not a regular file?)")
        finally:
            if self._log is not None:
                self._log.close()
                self._log = None

    def __enter__(self) -> Self:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.close()
        else:
            with contextlib.suppress(Exception):
                self.close()

    @contextlib.contextmanager
    def _quiet(self, what: str) -> Iterator[None]:
        """Send what OpenCV and FFmpeg print on file descriptor 2 to the log file while inside."""
        log = self._log
        if log is None:
            yield
            return
        try:
            if sys.stderr is not None:
                sys.stderr.flush()
            saved = os.dup(2)
        except (OSError, ValueError):   # no stderr to protect (closed, or a closed pipe)
            yield
            return
        try:
            os.dup2(log.fileno(), 2)
            yield
        finally:
            os.dup2(saved, 2)
            os.close(saved)

    def _reason(self, default: str) -> str:
        """The last line FFmpeg or OpenCV logged, without its ``[ERROR:0@0.1] file:line`` prefix."""
        if self._log is None:
            return default
        self._log.seek(0)
        lines = [ln.strip() for ln in self._log.read().decode("utf-8", "replace").splitlines() if ln.strip()]
        self._log.close()
        self._log = None
        for line in reversed(lines):
            if "Failed to initialize VideoWriter" in line:
                continue
            if line.startswith("[") and "]" in line:
                line = line.split("]", 1)[1].strip()
            return f"{default} ({line})"
        return default
