"""A live dynamic texture in a pygame game loop: scrolled across the window, steered by keys.

    pip install -e ".[examples]"        # or ./install.sh examples: pygame, beside the base install
    python examples/game_loop.py [DB.h5 [--texture NAME]] [--mode MODE] [--fps 60]

Without a database it analyses the built-in ripples clip first (a few seconds). Keys: Up/Down
playback speed, R reverse, +/- noise intensity, Left/Right scroll speed, Esc quits.

The loop shows how a game embeds the player: it asks for the next frame with ``start_frame``
*before* drawing the current one, so that the device renders while pygame draws and the
display flips, and only then ``wait``s for it; two frame buffers take turns. Frames come as
BGRA, the byte order of pygame's 32-bit display surfaces on little-endian machines, so the
buffer becomes a surface with no conversion. Every second it prints the frame rate it reaches
(on stderr) and it warns once when a frame's work overran the budget. Modes lds and mixture
render ``--lookahead`` frames per pass over their basis (each frame of a large texture reads
the whole basis: one frame at a time is bound by memory bandwidth); a key press still applies
from the next frame. ``--frames N`` stops after
N frames and prints a JSON summary (frames drawn, frame rate, mean time of the loop's own work
against the frame budget, frames over budget), and
``--autopilot`` presses the keys by itself: that is how the test suite runs it headless
(``SDL_VIDEODRIVER=dummy``).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time

import numpy as np

os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
try:
    import pygame
except ModuleNotFoundError:  # the base install has no pygame
    sys.exit('examples/game_loop.py needs pygame: pip install -e ".[examples]" (or ./install.sh examples)')

from dynatex.checks import Size  # noqa: E402
from dynatex.player import open_player, player_class  # noqa: E402
from dynatex.player.modes import default_mode  # noqa: E402
from dynatex.tiledb import TileDB  # noqa: E402

#: Frame -> key the autopilot presses, spread over a short run.
AUTOPILOT = {30: pygame.K_UP, 60: pygame.K_r, 90: pygame.K_PLUS, 120: pygame.K_RIGHT}


def sample_database(folder: str) -> str:
    """Analyse the built-in ripples clip with LDS into ``folder/ripples.h5``."""
    from dynatex.analyzer import load_clip
    from dynatex.analyzer.lds import learn_lds
    from dynatex.sample import ripples
    from dynatex.tiledb import DatabaseWriter

    clip = load_clip(ripples(120, 96, 128))
    path = os.path.join(folder, "ripples.h5")
    with DatabaseWriter(path) as w:
        w.put_texture("ripples", clip.source_info())
        w.put_method("ripples", "lds", learn_lds(clip))
    return path


class Controls:
    """What the keys change: playback speed and direction, noise intensity, scroll speed."""

    def __init__(self, player) -> None:
        self.player = player
        self.speed = 1.0
        self.direction = 1.0
        self.scroll = 60.0  # pixels per second

    def key(self, key: int) -> None:
        p = self.player
        if key == pygame.K_UP:
            self.speed = min(self.speed + 0.25, 2.0)
        elif key == pygame.K_DOWN:
            self.speed = max(self.speed - 0.25, 0.25)
        elif key == pygame.K_r:
            self.direction = -self.direction
        elif key in (pygame.K_PLUS, pygame.K_EQUALS, pygame.K_KP_PLUS) and hasattr(p, "intensity"):
            p.intensity = min(p.intensity + 0.25, 3.0)
        elif key in (pygame.K_MINUS, pygame.K_KP_MINUS) and hasattr(p, "intensity"):
            p.intensity = max(p.intensity - 0.25, 0.0)
        elif key == pygame.K_RIGHT:
            self.scroll += 30.0
        elif key == pygame.K_LEFT:
            self.scroll -= 30.0
        try:
            p.speed = self.speed * self.direction
        except ValueError:  # a mode that only plays forward
            p.speed = self.speed

    def state(self) -> dict:
        return {"speed": self.player.speed, "intensity": getattr(self.player, "intensity", None), "scroll": self.scroll}


class RateMeter:
    """The frame rate the loop reaches, printed every ``every`` seconds, and one warning the first
    time a frame's work overruns the budget (the count of such frames goes in the summary)."""

    def __init__(self, budget: float, every: float = 1.0, out=sys.stderr) -> None:
        self.budget, self.every, self.out = budget, every, out
        self.start = self.mark = time.perf_counter()
        self.frames = self.marked = self.over = 0

    def frame(self, work: float) -> None:
        self.frames += 1
        if work > self.budget:
            self.over += 1
            if self.over == 1:
                print(
                    f"game_loop: warning: frame {self.frames} took {1000 * work:.1f} ms, over the "
                    f"{1000 * self.budget:.1f} ms budget (said once; the summary counts them)",
                    file=self.out,
                )
        now = time.perf_counter()
        if now - self.mark >= self.every:
            print(f"game_loop: {(self.frames - self.marked) / (now - self.mark):.1f} fps", file=self.out)
            self.mark, self.marked = now, self.frames

    def fps(self) -> float:
        """Frames per second over the whole run."""
        return self.frames / max(time.perf_counter() - self.start, 1e-9)


def run(args: argparse.Namespace, db: str) -> dict:
    pygame.display.init()  # video only: no audio device needed
    try:
        screen = pygame.display.set_mode(args.window[::-1])  # pygame sizes are (width, height)
        pygame.display.set_caption("dynatex: Up/Down speed, R reverse, +/- intensity, Left/Right scroll")
        mode = args.mode
        if mode is None:
            with TileDB(db) as tdb:
                mode = default_mode(tdb.texture(args.texture))
        ahead = {"lookahead": args.lookahead} if "lookahead" in [o.name for o in player_class(mode).options] else {}
        with open_player(db, args.texture, mode=mode, backend=args.backend, format="BGRA", **ahead) as player:
            return _loop(args, screen, player)
    finally:
        pygame.quit()


def _loop(args: argparse.Namespace, screen, player) -> dict:
    h, w = player.shape[:2]
    buffers = [np.empty(player.shape, np.uint8) for _ in range(2)]
    surfaces = [pygame.image.frombuffer(b, (w, h), "BGRA") for b in buffers]  # views of the buffers
    controls = Controls(player)
    clock = pygame.time.Clock()
    budget = 1.0 / args.fps
    pending = player.start_frame(buffers[0])
    shown, offset, work, frames = 0, 0.0, 0.0, 0
    meter = RateMeter(budget)
    running = True
    while running and (args.frames is None or frames < args.frames):
        t0 = time.perf_counter()
        for event in pygame.event.get():
            if event.type == pygame.QUIT or (event.type == pygame.KEYDOWN and event.key == pygame.K_ESCAPE):
                running = False
            elif event.type == pygame.KEYDOWN:
                controls.key(event.key)
        if args.autopilot and frames in AUTOPILOT:
            controls.key(AUTOPILOT[frames])
        pending.wait()  # frame `shown` is complete
        nxt = 1 - shown
        pending = player.start_frame(buffers[nxt])  # the device renders it while we draw
        offset = (offset + controls.scroll * budget) % w
        surface = surfaces[shown]
        for y in range(0, args.window[0], h):  # the texture tiled across the window, scrolling
            for x in range(-int(offset), args.window[1], w):
                screen.blit(surface, (x, y))
        pygame.display.flip()
        spent = time.perf_counter() - t0
        work += spent
        meter.frame(spent)
        shown = nxt
        frames += 1
        clock.tick(args.fps)
    pending.wait()
    shot = pygame.surfarray.array3d(screen)
    return {
        "frames": frames,
        "mean_work_ms": round(1000 * work / max(frames, 1), 3),
        "budget_ms": round(1000 * budget, 3),
        "fps": round(meter.fps(), 1),
        "over_budget": meter.over,
        "backend": player.backend,
        "texture": f"{w}x{h}",
        "window_std": round(float(shot.std()), 2),
        **controls.state(),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("database", nargs="?", help="tile database (default: analyse the built-in ripples)")
    ap.add_argument("--texture")
    ap.add_argument("--mode", default=None, help="player mode (default: the texture's own)")
    ap.add_argument("--backend", default="auto", choices=("auto", "opencl", "numpy"))
    ap.add_argument(
        "--lookahead",
        type=int,
        default=8,
        help="frames the player renders ahead, k per pass over the basis (modes lds and mixture; 1: one "
        "at a time; a key press discards them, so it applies from the next frame)",
    )
    ap.add_argument("--fps", type=float, default=60.0, help="target frame rate (the frame budget is 1/fps)")
    ap.add_argument(
        "--window",
        type=Size(4096).parse,  # WxH -> (height, width), each side checked
        default=(360, 640),
        metavar="WxH",
        help="window size (default 640x360)",
    )
    ap.add_argument("--frames", type=int, default=None, help="stop after this many frames and print a summary")
    ap.add_argument("--autopilot", action="store_true", help="press the keys by itself (for tests)")
    args = ap.parse_args(argv)
    if not (1.0 <= args.fps <= 1000.0):
        ap.error(f"--fps must be in [1, 1000], not {args.fps:g}")
    with tempfile.TemporaryDirectory() as tmp:
        db = args.database or sample_database(tmp)
        summary = run(args, db)
    if args.frames is not None:
        print(json.dumps(summary))
    return 0


if __name__ == "__main__":
    sys.exit(main())
