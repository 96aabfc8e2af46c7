"""Writing rendered frames: H.264 MP4 (PyAV), MPEG-4 MKV and Motion JPEG AVI (OpenCV), animated
WebP, PNG (APNG) and GIF (Pillow), or numbered PNG files; the output's extension chooses.

Every way this can fail ends in one :class:`OutputError` naming the output and the reason:
a frame rate or frame size the format refuses is refused here before an encoder sees it (an
infinite frame rate made FFmpeg loop for ever), FFmpeg's own log lines are kept off the
terminal and the last of them becomes the reason, and a video or animation that cannot be
read back whole after closing (disk full, a device instead of a file) is an error, not a
silent loss.
"""

from __future__ import annotations

import contextlib
import math
import os
import sys
import tempfile
import time
from collections.abc import Iterator
from dataclasses import dataclass
from fractions import Fraction
from typing import TYPE_CHECKING

import numpy as np

from ..errors import InvalidArgumentError, OutputError

if TYPE_CHECKING:
    from typing_extensions import Self

#: Frame rates every container below writes and reads back: FFmpeg's MPEG-4 encoder refuses
#: a time base finer than 1/65535 and OpenCV cannot open one coarser than 1/100 s.
MIN_FPS = 0.01
MAX_FPS = 1000.0


#: Constant rate factor of the H.264 encoder (0-51: lower is better and larger; x264's own
#: default is 23). With the default preset, 15 keeps 35 dB PSNR against the rendered frames
#: on every frame of the hardest content we have (1080p grass tiles, ~125 Mbit/s there;
#: smooth textures take far less).
H264_CRF = 15
#: x264 presets, fastest first: each slower one makes a smaller file at the same CRF
H264_PRESETS = ("ultrafast", "superfast", "veryfast", "faster", "fast", "medium", "slow", "slower", "veryslow")
#: the default preset: a quarter of veryfast's encoder time at a higher PSNR (CRF 15 against
#: 17) for 45% more bytes, so that a video is written at about the rendering's pace on two
#: cores; ``--preset veryfast --crf 16`` or slower for smaller files (README, Performance)
H264_PRESET = "ultrafast"
#: swscale's filter for RGB -> yuv420p: a 2x2 box average of the chroma (the format's own
#: sampling), faster than its bicubic default and as close after the round trip
H264_CHROMA_FILTER = "AREA"
#: outputs expected to take longer than this many seconds show a progress bar (on a terminal)
PROGRESS_DELAY = 2.0
#: Animated images are encoded when closed, from frames held in memory up to this many bytes.
MAX_ANIMATION_BYTES = 2**30


@dataclass(frozen=True)
class VideoCodec:
    fourcc: str  # OpenCV's fourcc, or the FFmpeg encoder when ``library`` is "pyav"
    label: str
    min_side: int  # width and height the encoder accepts
    max_side: int
    library: str = "opencv"


VIDEO_CODECS = {
    # yuv420p halves the chroma resolution: odd sides are padded by repeating the last row or column
    ".mp4": VideoCodec("libx264", "H.264 (yuv420p)", 2, 8191, "pyav"),
    ".mkv": VideoCodec("XVID", "MPEG-4 (XVID)", 2, 8191),
    ".avi": VideoCodec("MJPG", "Motion JPEG", 1, 65535),
}


@dataclass(frozen=True)
class Animation:
    """An animated image format Pillow writes: frame delays are whole ``tick`` seconds."""

    pillow: str  # Pillow's format name
    label: str
    max_side: int
    tick: float  # seconds per unit of the format's frame delay
    min_delay: int  # shortest delay (ticks) players honour
    max_delay: int  # longest delay (ticks) the format stores

    def fps_range(self) -> tuple[float, float]:
        return max(MIN_FPS, 1 / (self.max_delay * self.tick)), min(MAX_FPS, 1 / (self.min_delay * self.tick))

    def delays(self, count: int, fps: float) -> list[int]:
        """Delays (ticks) of ``count`` frames at ``fps``: rounded so that the total never drifts."""
        ends = [round((i + 1) / (fps * self.tick)) for i in range(count)]
        return [max(self.min_delay, e - s) for s, e in zip([0] + ends[:-1], ends)]


ANIMATIONS = {
    # browsers show GIF delays under 2/100 s as 1/10 s
    ".gif": Animation("GIF", "animated GIF", 65535, 0.01, 2, 65535),
    ".webp": Animation("WEBP", "animated WebP", 16383, 0.001, 1, 2**24 - 1),
    ".apng": Animation("PNG", "animated PNG", 2**31 - 1, 0.001, 1, 65535),
}


def check_fps(fps: float, what: str = "frame rate") -> float:
    """``fps`` as a float in ``[MIN_FPS, MAX_FPS]``, else an :class:`OutputError`."""
    try:
        v = float(fps)
    except (TypeError, ValueError):
        raise OutputError(f"{what} must be a number, not {fps!r}") from None
    if not (math.isfinite(v) and MIN_FPS <= v <= MAX_FPS):
        raise OutputError(
            f"{what} must be a finite number in [{MIN_FPS:g}, {MAX_FPS:g}] frames per second, not {fps!r}"
        )
    return v


class FrameWriter:
    """Writes ``(H, W, 3)`` RGB uint8 frames to ``output``: a video (``.mp4`` H.264, ``.mkv``,
    ``.avi``), an animated image (``.webp``, ``.apng``, ``.gif``, looping for ever), a ``.png``
    pattern (``%d`` in it, else ``NAME_00000.png``...) or a folder (``frame_00000.png``...).

    Call :meth:`open` with the frame shape and rate before the first :meth:`write`, so that a
    refusal comes before any rendering; :meth:`close` checks that the output reads back whole.
    ``crf`` and ``preset`` set the H.264 encoder (:data:`H264_CRF`, :data:`H264_PRESET`; x264
    runs on every core). With ``progress``, a bar on stderr (a terminal only) counts the frames
    written and, for an animated image, the frames encoded at close, once an output has taken
    :data:`PROGRESS_DELAY` seconds.
    """

    def __init__(self, output: str, *, crf: int = H264_CRF, preset: str = H264_PRESET, progress: bool = False) -> None:
        if isinstance(crf, bool) or not isinstance(crf, (int, np.integer)) or not 0 <= crf <= 51:
            raise InvalidArgumentError(f"crf must be an integer in [0, 51], not {crf!r}")
        if preset not in H264_PRESETS:
            raise InvalidArgumentError(f"preset must be one of {H264_PRESETS}, not {preset!r}")
        self.crf, self.preset, self.progress = int(crf), preset, bool(progress)
        self._bar = None
        self._stage, self._stage_start = "", 0.0
        self.output = output
        self.index = 0
        self._video = None
        self._codec: VideoCodec | None = None
        self._animation: Animation | None = None
        self._frames: list[np.ndarray] = []
        self._fps = 0.0
        self._shape: tuple[int, int] | None = None
        self._log = None
        low = output.lower()
        ext = os.path.splitext(low)[1]
        if low.endswith(".png"):
            self.kind = "png"
            self.pattern = output if "%" in output else output[:-4] + "_%05d.png"
        elif os.path.isdir(output) or output.endswith(os.sep):
            self.kind = "png"
            self.pattern = os.path.join(output, "frame_%05d.png")
        elif ext in VIDEO_CODECS:
            self.kind = "video"
            self._codec = VIDEO_CODECS[ext]
        elif ext in ANIMATIONS:
            self.kind = "animation"
            self._animation = ANIMATIONS[ext]
        else:
            raise OutputError(
                f"output {output!r}: use {', '.join([*VIDEO_CODECS, *ANIMATIONS])}, a .png pattern or a folder"
            )
        if self.kind == "png":
            try:
                self.pattern % 0
            except (TypeError, ValueError):
                raise OutputError(f"output {output!r}: the .png pattern needs one integer field like %05d") from None
        folder = os.path.dirname(os.path.abspath(self.pattern if self.kind == "png" else output))
        if not (os.path.isdir(folder) or (self.kind == "png" and folder == os.path.abspath(output))):
            raise OutputError(f"output folder {folder} does not exist")

    def open(self, shape: tuple[int, ...], fps: float, frames: int | None = None) -> None:
        """Prepare to write frames of ``shape`` (H, W[, 3]) at ``fps``; raise :class:`OutputError` if the
        output cannot take them. ``frames``: how many will come (the progress bar's total)."""
        h, w = int(shape[0]), int(shape[1])
        self._shape = (h, w)
        self._total = frames
        if self.kind == "png":
            folder = os.path.dirname(os.path.abspath(self.pattern))
            try:
                os.makedirs(folder, exist_ok=True)
            except OSError as exc:
                raise OutputError(f"cannot create output folder {folder}: {exc.strerror or exc}") from None
            return
        fps = self._fps = check_fps(fps, f"frame rate of {self.output}")
        if self.kind == "animation":
            self._check_animation(h, w, fps)
            self._touch()
            return
        codec = self._codec
        assert codec is not None
        if not (codec.min_side <= w <= codec.max_side and codec.min_side <= h <= codec.max_side):
            fits = [
                f"{ext} ({c.label})"
                for ext, c in VIDEO_CODECS.items()
                if c.min_side <= min(w, h) and max(w, h) <= c.max_side
            ]
            raise OutputError(
                f"cannot write {w}x{h} frames to {self.output}: {codec.label} takes widths and "
                f"heights {codec.min_side}..{codec.max_side}; use {' or '.join(fits + ['PNG frames'])}"
            )
        existed = self._touch()
        self._log = tempfile.TemporaryFile()  # noqa: SIM115 (kept open until close(): FFmpeg's log)
        with self._quiet("cannot open"):
            self._video = (
                self._open_pyav(codec, h, w, fps) if codec.library == "pyav" else self._open_opencv(codec, h, w, fps)
            )
        if self._video is None:
            if not existed and os.path.isfile(self.output) and os.path.getsize(self.output) == 0:
                os.unlink(self.output)  # OpenCV leaves an empty file behind
            library = "PyAV" if codec.library == "pyav" else "OpenCV"
            raise OutputError(f"cannot write video {self.output}: {self._reason(f'{library} refused to open it')}")

    def _touch(self) -> bool:
        """Create the output file, so that the OS's reason for refusing it reaches the user; whether it existed."""
        existed = os.path.lexists(self.output)
        if os.path.exists(self.output) and not os.path.isfile(self.output):
            raise OutputError(f"cannot write {self.output}: it exists and is not a regular file")
        try:  # the OS's reason, which the encoders would swallow
            os.close(os.open(self.output, os.O_WRONLY | os.O_CREAT | getattr(os, "O_NONBLOCK", 0), 0o666))
        except OSError as exc:
            raise OutputError(f"cannot write {self.output}: {exc.strerror or exc}") from None
        return existed

    def _check_animation(self, h: int, w: int, fps: float) -> None:
        anim = self._animation
        assert anim is not None
        if not (1 <= w <= anim.max_side and 1 <= h <= anim.max_side):
            raise OutputError(
                f"cannot write {w}x{h} frames to {self.output}: {anim.label} takes widths and "
                f"heights 1..{anim.max_side}; use .mp4 or PNG frames"
            )
        lo, hi = anim.fps_range()
        if not lo <= fps <= hi:
            raise OutputError(
                f"cannot write {self.output} at {fps:g} frames per second: {anim.label} frame "
                f"delays take [{lo:.4g}, {hi:.4g}] frames per second; use .mp4 or another --fps"
            )

    def _open_opencv(self, codec: VideoCodec, h: int, w: int, fps: float):
        import cv2

        video = cv2.VideoWriter(self.output, cv2.VideoWriter_fourcc(*codec.fourcc), fps, (w, h))
        return video if video.isOpened() else None

    def _open_pyav(self, codec: VideoCodec, h: int, w: int, fps: float):
        import av

        try:
            container = av.open(self.output, "w", format="mp4", options={"movflags": "+faststart"})
        except (av.FFmpegError, OSError) as exc:
            self._log_line(str(exc))
            return None
        try:
            stream = container.add_stream(codec.fourcc, rate=Fraction(fps).limit_denominator(100_000))
            stream.width, stream.height = w + w % 2, h + h % 2
            stream.pix_fmt = "yuv420p"
            stream.options = {"crf": str(self.crf), "preset": self.preset}
            stream.codec_context.thread_count = 0  # x264 chooses: every core
            stream.codec_context.open()
        except (av.FFmpegError, OSError, ValueError) as exc:
            container.close()
            self._log_line(str(exc))
            return None
        return container, stream

    def _log_line(self, line: str) -> None:
        if self._log is not None:
            self._log.write(line.encode("utf-8", "replace") + b"\n")

    def write(self, frame: np.ndarray) -> None:
        """Append one RGB frame (the shape given to :meth:`open`)."""
        if self._shape is None:
            raise RuntimeError("FrameWriter.open must come before write")
        if frame.shape[:2] != self._shape:
            raise InvalidArgumentError(
                f"frame is {frame.shape[1]}x{frame.shape[0]}, the output was opened for "
                f"{self._shape[1]}x{self._shape[0]}"
            )
        if self.kind == "animation":
            if (self.index + 1) * frame[..., :3].nbytes > MAX_ANIMATION_BYTES:
                raise OutputError(
                    f"cannot write {self.output}: animated images are encoded from memory, at most "
                    f"{MAX_ANIMATION_BYTES >> 20} MiB of frames; use .mp4 or fewer frames"
                )
            self._frames.append(np.array(frame[..., :3], np.uint8))
        elif self.kind == "png":
            import cv2

            path = self.pattern % self.index
            ok, data = cv2.imencode(".png", cv2.cvtColor(frame, cv2.COLOR_RGB2BGR))
            if not ok:
                raise OutputError(f"cannot encode frame {self.index} as PNG")
            try:
                with open(path, "wb") as f:
                    f.write(data.tobytes())
            except OSError as exc:
                raise OutputError(f"cannot write {path}: {exc.strerror or exc}") from None
        elif self._video is None:
            raise OutputError(f"video {self.output} is not open")
        elif isinstance(self._video, tuple):
            self._write_pyav(frame)
        else:
            import cv2

            with self._quiet("cannot write"):
                self._video.write(cv2.cvtColor(frame, cv2.COLOR_RGB2BGR))
        self.index += 1
        if self.progress:
            self._advance("writing", self.index, self._total)

    def _advance(self, what: str, done: int, total: int | None) -> None:
        """Move the progress bar of stage ``what`` to ``done`` of ``total``: a new bar per stage,
        drawn once the stage has taken :data:`PROGRESS_DELAY` seconds (on a terminal only)."""
        now = time.monotonic()
        if self._stage != what:
            self._end_bar()
            self._stage, self._stage_start = what, now
        if self._bar is None:
            if now - self._stage_start < PROGRESS_DELAY or sys.stderr is None or not sys.stderr.isatty():
                return
            from tqdm import tqdm

            self._bar = tqdm(total=total, desc=what, unit="frame", file=sys.stderr, leave=False)
        self._bar.n = done
        self._bar.refresh()

    def _end_bar(self) -> None:
        if self._bar is not None:
            self._bar.close()
            self._bar = None

    def _write_pyav(self, frame: np.ndarray) -> None:
        import av

        container, stream = self._video
        h, w = self._shape
        rgb = np.ascontiguousarray(frame[..., :3])
        if h % 2 or w % 2:
            rgb = np.pad(rgb, ((0, h % 2), (0, w % 2), (0, 0)), mode="edge")
        vf = av.VideoFrame.from_ndarray(rgb, format="rgb24").reformat(
            format="yuv420p", interpolation=H264_CHROMA_FILTER
        )
        vf.pts = self.index
        vf.time_base = 1 / stream.codec_context.framerate
        try:
            with self._quiet("cannot write"):
                container.mux(stream.encode(vf))
        except (av.FFmpegError, OSError) as exc:
            raise OutputError(f"cannot write video {self.output}: {exc}") from None

    def close(self) -> None:
        """Finish the video or animation and check that it reads back with every frame written."""
        try:
            self._close()
        finally:
            self._end_bar()

    def _close(self) -> None:
        if self.kind == "animation":
            if self._frames:
                self._close_animation()
            elif self._shape is not None and os.path.isfile(self.output) and os.path.getsize(self.output) == 0:
                os.unlink(self.output)  # opened, no frame written: no empty file left behind
            return
        if self._video is None:
            return
        video, self._video = self._video, None
        try:
            with self._quiet("cannot finish"):
                count = self._close_pyav(video) if isinstance(video, tuple) else self._close_opencv(video)
            if count < self.index:
                raise OutputError(
                    f"video {self.output} is incomplete: {count} of {self.index} frames read back "
                    f"({_why_incomplete(self.output)})"
                )
        finally:
            if self._log is not None:
                self._log.close()
                self._log = None

    def _close_opencv(self, video) -> int:
        import cv2

        video.release()
        cap = cv2.VideoCapture(self.output)
        count = int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) if cap.isOpened() else 0
        cap.release()
        return max(count, 0)  # a truncated file's header can give any number

    def _close_pyav(self, video) -> int:
        import av

        container, stream = video
        try:
            container.mux(stream.encode(None))
            container.close()
        except (av.FFmpegError, OSError) as exc:
            raise OutputError(f"cannot finish video {self.output}: {exc}") from None
        try:
            with av.open(self.output) as back:
                return back.streams.video[0].frames if back.streams.video else 0
        except (av.FFmpegError, OSError):
            return 0

    def _close_animation(self) -> None:
        from PIL import Image

        anim = self._animation
        assert anim is not None
        frames, self._frames = self._frames, []
        delays = anim.delays(len(frames), self._fps)
        ms = [round(d * anim.tick * 1000) for d in delays]
        rest = _Images(frames[1:], lambda i: self.progress and self._advance("encoding", i + 2, len(frames)))
        extra = {"lossless": False, "quality": 90, "method": 4} if anim.pillow == "WEBP" else {}
        try:
            Image.fromarray(frames[0], "RGB").save(
                self.output, format=anim.pillow, save_all=True, append_images=rest, duration=ms, loop=0, **extra
            )
        except (OSError, ValueError) as exc:
            raise OutputError(f"cannot write {self.output}: {getattr(exc, 'strerror', None) or exc}") from None
        total = read_animation(self.output)[1] if os.path.isfile(self.output) else None
        if total is None or abs(sum(ms) - sum(total)) > len(frames):
            got = "nothing" if total is None else f"{sum(total)} ms of {sum(ms)} ms"
            raise OutputError(
                f"{anim.label} {self.output} is incomplete: {got} read back ({_why_incomplete(self.output)})"
            )

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
        except (OSError, ValueError):  # no stderr to protect (closed, or a closed pipe)
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


def _why_incomplete(output: str) -> str:
    """Why an output file did not read back whole, as far as the file system tells."""
    try:
        full = os.statvfs(os.path.dirname(os.path.abspath(output))).f_bavail == 0
    except (OSError, AttributeError):
        full = False
    return "no space left on device" if full else "disk full, or not a regular file?"


class _Images:
    """Frames as Pillow images, made as Pillow iterates (it may iterate twice); ``seen(i)`` after
    frame ``i`` is handed out (the encoder's progress)."""

    def __init__(self, frames: list[np.ndarray], seen) -> None:
        self.frames, self.seen = frames, seen

    def __len__(self) -> int:
        return len(self.frames)

    def __iter__(self):
        from PIL import Image

        for i, f in enumerate(self.frames):
            yield Image.fromarray(f, "RGB")
            self.seen(i)


def read_animation(path: str) -> tuple[int, list[int]] | None:
    """Frame count and per-frame delays (ms) of an animated image, or None if Pillow cannot read it.

    Consecutive identical frames may be stored as one longer frame, so the delays, not the
    count, say whether every frame is there.
    """
    from PIL import Image

    try:
        with Image.open(path) as im:
            n = getattr(im, "n_frames", 1)
            delays = []
            for i in range(n):
                im.seek(i)
                im.load()  # WebP sets a frame's duration when it decodes it
                delays.append(int(im.info.get("duration", 0)))
            return n, delays
    except (OSError, ValueError, EOFError):
        return None
