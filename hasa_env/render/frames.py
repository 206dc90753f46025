"""Frames of a recording: PNG files and videos of the driver's or the top-down view.

The frames are drawn from the recorded rows themselves (each row holds the
info keys), headless; used by ``hasa-replay --frames/--video``.
"""

from __future__ import annotations

import io
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from hasa_env.atomic import write_atomic
from hasa_env.render import make_renderer, surface_to_array
from hasa_env.sim.config import deep_merge
from hasa_env.sim.setup import INFO_KEYS, build_setup

__all__ = ["write_frames"]


def write_frames(
    recording: Any,
    directory: str | os.PathLike[str] | None,
    *,
    every: int = 10,
    view: str = "driver",
    size: tuple[int, int] = (1280, 720),
    show_points: bool = False,
    weights: np.ndarray | None = None,
    video: str | os.PathLike[str] | None = None,
    log: Callable[[str], None] = print,
) -> list[Path]:
    """Render every ``every``-th row of a recording as PNG frames and/or a video.

    The frames are drawn from the recorded rows themselves (the row's info
    keys), headless. ``weights`` (rows, C) puts an estimator's hypothesis
    weights into the HUD. The video (``.mp4``, ``.gif``, ...; frame rate
    ``100 / every`` for 100 Hz recordings, i.e. real time) needs ``imageio``
    (and ``imageio-ffmpeg`` for mp4); without them it is skipped with a message.

    Each PNG is written to a new randomly named temporary file and moved into
    place (:func:`hasa_env.atomic.write_atomic`), so a file or symlink already
    at ``frame_NNNNN.png`` is replaced, never written through.

    Returns:
        The PNG files written.
    """
    os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
    import pygame  # only when frames are written: the headless analysis paths never load it

    config = deep_merge(
        recording.config,
        {"render": {"width": size[0], "height": size[1], "show_points": show_points}},
    )
    setup = build_setup(config)
    renderer = make_renderer(setup, "rgb_array", view=view)
    data = recording.data
    out = Path(directory) if directory is not None else None
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
    writer = None
    if video is not None:
        try:
            import imageio.v2 as imageio  # optional: only for --video

            fps = 1.0 / (recording.dt * every)
            writer = imageio.get_writer(str(video), fps=fps)
        except Exception as exc:  # noqa: BLE001 - missing imageio / ffmpeg plugin: skip cleanly
            log(
                f"hasa-replay: no video ({exc.__class__.__name__}: {exc}); "
                "install imageio and imageio-ffmpeg"
            )
            writer = None
    written: list[Path] = []
    columns = {k: data[k].to_numpy() for k in INFO_KEYS}
    try:
        for row in range(0, len(data), every):
            info = {k: columns[k][row].item() for k in INFO_KEYS}
            w = None if weights is None else list(weights[row])
            surface = renderer.draw(info, w)
            if out is not None:
                path = out / f"frame_{row:05d}.png"
                png = io.BytesIO()
                pygame.image.save(surface, png, "png")
                # a new random temporary name + os.replace: never through a pre-placed symlink
                write_atomic(path, png.getvalue(), fsync=False)
                written.append(path)
            if writer is not None:
                writer.append_data(surface_to_array(surface))
    finally:
        if writer is not None:
            writer.close()
            log(f"hasa-replay: wrote {video}")
        renderer.close()
    return written
