"""Rendering speed: frames per second of the driver's-eye view at 1280x720.

The issue's target: the driver's view runs smoothly at 60 fps at 1280x720
while the simulation runs at 100 Hz in real time. Measured here, headless
(``SDL_VIDEODRIVER=dummy``), on frames of a drive along the curved track
(bends, posts, ghost markings, near/far points and the HUD with weights):

- ``driver_draw``: :meth:`hasa_env.render.driver_view.DriverViewRenderer.draw` onto an
  off-screen surface (the drawing work of one frame);
- ``driver_rgb_array``: the same plus the copy into an (H, W, 3) array
  (``render_mode="rgb_array"``, what ``hasa-replay --frames`` and RL users pay);
- ``driver_window``: drawing straight onto the display surface plus
  ``display.flip()``, what ``hasa-drive`` does per frame;
- ``driver_with_physics``: ``driver_window`` plus 100/60 env steps per
  frame (the simulation's share of a frame at 100 Hz and 60 fps): the
  frame rate the whole loop could reach unthrottled;
- ``participant_with_physics``: the same with a study participant's view
  (:meth:`hasa_env.render.ViewOptions.participant`: no ghost markings, no
  HUD, bonnet and dashboard, road and grass bands), what ``hasa-drive
  study`` draws; ``participant_over_developer`` is its rate over
  ``driver_with_physics``, measured in the same run;
- ``top_down_draw``: the top-down view at the same size, for comparison;
- ``drive_loop``: :class:`hasa_env.session.DriveSession` itself in real time
  (keyboard input, frame cap 60 fps) for a few seconds: the frames it
  actually drew per second and how far the simulation clock lagged the
  wall clock.

Each measurement is repeated; the median is reported with the spread. By
default it runs headless (``SDL_VIDEODRIVER=dummy``, set unless the
environment chooses a driver); on a display (e.g. ``SDL_VIDEODRIVER=x11``)
the flip also pays the copy to the screen, so the window numbers drop.

Usage::

    python -m benchmarks.perf.render            # about 35 s
    python -m benchmarks.perf.render --quick    # a few seconds, rough numbers
    python -m benchmarks.perf.render --json render.json
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import statistics
import sys
import tempfile
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from hasa_env.devices import InputManager, init_pygame_input
from hasa_env.envs.lane_keeping import LaneKeepingEnv
from hasa_env.render import TopDownRenderer, ViewOptions, make_renderer
from hasa_env.session import DriveSession, DriveSettings

__all__ = ["run", "main", "format_table", "TARGETS", "SIZE"]

SIZE = (1280, 720)
TARGET_FPS = 60.0
SIM_FREQUENCY = 100.0
TARGETS: dict[str, tuple[str, float]] = {
    "driver_with_physics": ("driver view + 100 Hz physics, frames/s", TARGET_FPS),
    "driver_window": ("driver view to the window, frames/s", TARGET_FPS),
    "participant_with_physics": (
        "participant view (no ghosts/HUD, bonnet, road texture) + 100 Hz physics, frames/s",
        TARGET_FPS,
    ),
    "drive_loop": ("hasa-drive loop, frames drawn per s (capped at 60)", 0.95 * TARGET_FPS),
}


def _trajectory(steps: int) -> tuple[Any, list[dict[str, Any]]]:
    """Infos of a drive along the curved track (varied frames), and the env's set-up."""

    env = LaneKeepingEnv(
        config={
            "track": "curved",
            "action": {"type": "physical"},
            "time_limit": 1000.0,
            "render": {"width": SIZE[0], "height": SIZE[1], "show_points": True},
        }
    )
    _, info = env.reset(seed=0)
    infos = []
    for _ in range(steps):
        steer = (
            math.atan(2.8 * info["road_curvature"])
            - 0.05 * info["lateral_offset"]
            - 0.5 * info["heading"]
        )
        _, _, _, _, info = env.step([steer, 0.0])
        infos.append({**info, "estimate_weights": [0.3, 0.7]})
    return env, infos


def _rate(work: Callable[[int], None], frames: int, repeats: int) -> dict[str, Any]:
    work(min(frames, 10))  # warm up (fonts, caches)
    rates = []
    for _ in range(repeats):
        start = time.perf_counter()
        work(frames)
        rates.append(frames / (time.perf_counter() - start))
    return {
        "frames_per_second": statistics.median(rates),
        "min_frames_per_second": min(rates),
        "max_frames_per_second": max(rates),
        "frames": frames,
        "repeats": repeats,
    }


def _drive_loop(seconds: float) -> dict[str, Any]:
    """Run hasa-drive's real-time loop (keyboard, dummy window) and count frames."""
    import pygame  # pygame: after the SDL drivers are chosen above

    pg = init_pygame_input()
    display = pg.display.set_mode(SIZE)
    inputs = InputManager(use_joystick=False, pygame_module=pg)
    frames: list[float] = []
    lags: list[float] = []
    with tempfile.TemporaryDirectory() as tmp:
        settings = DriveSettings(
            participant="bench", seconds=seconds, runs=1, output=tmp, seed=0, countdown=0.0
        )

        def confirm(session: Any) -> None:
            if session.state == "idle":
                pg.event.post(pg.event.Event(pg.KEYDOWN, key=pg.K_SPACE, mod=0))

        session = DriveSession(
            settings,
            inputs,
            display=display,
            realtime=True,
            hook=confirm,
            fps=int(TARGET_FPS),
            log=lambda m: None,
        )
        draw = session._draw

        def counted(info: Any, message: Any = None) -> None:
            if session.state == "driving":
                now = time.perf_counter()
                frames.append(now)
                lags.append(now - session._anchor - float(info["time"]))
            draw(info, message)

        session._draw = counted  # type: ignore[method-assign]
        start = time.perf_counter()
        results = session.run()
        wall = time.perf_counter() - start
        session.close()
    pygame.display.quit()
    span = frames[-1] - frames[0] if len(frames) > 1 else math.nan
    return {
        "frames_per_second": (len(frames) - 1) / span if len(frames) > 1 else math.nan,
        "frames": len(frames),
        "sim_seconds": results[0].steps / SIM_FREQUENCY if results else math.nan,
        "wall_seconds": wall,
        "max_lag_seconds": max(lags) if lags else math.nan,
        "repeats": 1,
    }


def run(quick: bool = False, progress: Callable[[str], None] | None = None) -> dict[str, Any]:
    """Measure the rendering rates (see the module docstring); returns a JSON-able dict."""
    os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
    os.environ.setdefault("SDL_AUDIODRIVER", "dummy")
    os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
    import pygame  # pygame: after the SDL drivers are chosen above

    say = progress or (lambda message: None)
    frames = 60 if quick else 300
    repeats = 3 if quick else 5
    env, infos = _trajectory(frames)
    setup = env.setup
    driver = make_renderer(setup, "rgb_array", view="driver")
    top_down = TopDownRenderer(setup, "rgb_array")
    pygame.display.init()
    window = pygame.display.set_mode(SIZE)
    video_driver = pygame.display.get_driver()
    results: dict[str, Any] = {}

    def cycle(fn: Callable[[dict[str, Any]], Any]) -> Callable[[int], None]:
        def work(n: int) -> None:
            for i in range(n):
                fn(infos[i % len(infos)])

        return work

    say("driver view: draw")
    results["driver_draw"] = _rate(cycle(driver.draw), frames, repeats)
    say("driver view: rgb_array")
    results["driver_rgb_array"] = _rate(cycle(driver.render), frames, repeats)

    def to_window(info: dict[str, Any]) -> None:
        driver.draw(info, target=window)
        pygame.display.flip()

    say("driver view: window")
    results["driver_window"] = _rate(cycle(to_window), frames, repeats)
    steps_per_frame = SIM_FREQUENCY / TARGET_FPS
    sim: dict[str, Any] = {"owed": 0.0, "info": infos[0]}

    def with_physics(renderer: Any) -> Callable[[dict[str, Any]], None]:
        def frame(info: dict[str, Any]) -> None:
            sim["owed"] += steps_per_frame
            while sim["owed"] >= 1.0:
                i = sim["info"]
                steer = (
                    math.atan(2.8 * i["road_curvature"])
                    - 0.05 * i["lateral_offset"]
                    - 0.5 * i["heading"]
                )
                _, _, _, _, sim["info"] = env.step([steer, 0.0])
                sim["owed"] -= 1.0
            renderer.draw(sim["info"], target=window)
            pygame.display.flip()

        return frame

    say("driver view + physics")
    results["driver_with_physics"] = _rate(cycle(with_physics(driver)), frames, repeats)
    participant = make_renderer(
        setup, "rgb_array", view="driver", options=ViewOptions.participant()
    )
    say("participant view + physics")
    results["participant_with_physics"] = _rate(cycle(with_physics(participant)), frames, repeats)
    participant.close()
    say("top-down view: draw")
    results["top_down_draw"] = _rate(cycle(top_down.draw), frames, repeats)
    driver.close()
    env.close()
    say("hasa-drive loop (real time)")
    results["drive_loop"] = _drive_loop(1.5 if quick else 5.0)
    return _report(quick, results, video_driver)


def _report(quick: bool, results: dict[str, Any], video_driver: str) -> dict[str, Any]:
    """:func:`run`'s report: the measured ``results``, each target's ratio (measured / target),
    the participant-over-developer ratio and the machine."""
    import pygame  # (imported by run, after the SDL drivers are chosen)

    ratios = {
        key: results[key]["frames_per_second"] / target
        for key, (_, target) in TARGETS.items()
        if key in results
    }
    extra = {
        "participant_over_developer": results["participant_with_physics"]["frames_per_second"]
        / results["driver_with_physics"]["frames_per_second"]
    }
    return {
        "size": list(SIZE),
        "target_fps": TARGET_FPS,
        "sim_frequency": SIM_FREQUENCY,
        "quick": quick,
        "results": results,
        "ratios_to_target": ratios,
        "ratios": extra,
        "machine": {
            "python": platform.python_version(),
            "platform": platform.platform(),
            "cpus": os.cpu_count(),
            "pygame": pygame.version.ver,
            "video_driver": video_driver,
            "sdl": ".".join(map(str, pygame.get_sdl_version())),
            "numpy": np.__version__,
        },
    }


def format_table(report: dict[str, Any]) -> str:
    """A readable table of a :func:`run` report, with the targets."""
    w, h = report["size"]
    machine = report["machine"]
    lines = [
        f"Driver's-eye view at {w}x{h}, SDL video driver {machine['video_driver']!r} "
        f"(pygame {machine['pygame']}, SDL {machine['sdl']}, {machine['cpus']} CPUs)"
    ]
    lines.append(f"{'measurement':22s} {'frames/s':>10s} {'min':>8s} {'max':>8s}  target")
    for key, r in report["results"].items():
        fps = r["frames_per_second"]
        lo = r.get("min_frames_per_second", math.nan)
        hi = r.get("max_frames_per_second", math.nan)
        target = ""
        if key in TARGETS:
            text, value = TARGETS[key]
            ratio = report["ratios_to_target"][key]
            verdict = "met" if ratio >= 1.0 else "NOT met"
            target = f">= {value:g} ({text}): {ratio:.2f}x, {verdict}"
        lines.append(f"{key:22s} {fps:10.1f} {lo:8.1f} {hi:8.1f}  {target}")
    loop = report["results"]["drive_loop"]
    lines.append(
        f"drive loop: {loop['sim_seconds']:.2f} s simulated in {loop['wall_seconds']:.2f} s wall "
        f"(incl. start-up); at a frame the simulation clock was at most "
        f"{1000 * loop['max_lag_seconds']:.1f} ms behind the wall clock (one step is 10 ms)"
    )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """``python -m benchmarks.perf.render [--quick] [--json FILE]``."""
    parser = argparse.ArgumentParser(
        allow_abbrev=False,
        prog="python -m benchmarks.perf.render",
        description=__doc__.splitlines()[0],
    )
    parser.add_argument(
        "--quick", action="store_true", help="fewer frames and repeats (rough numbers)"
    )
    parser.add_argument("--json", default=None, help="also write the report to this JSON file")
    args = parser.parse_args(argv)
    report = run(
        quick=args.quick, progress=lambda m: print(f"  measuring {m} ...", file=sys.stderr)
    )
    print(format_table(report))
    if args.json:
        with open(args.json, "w", encoding="utf-8") as f:
            json.dump(report, f, indent=2)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
