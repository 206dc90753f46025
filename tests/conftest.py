"""Test set-up: headless pygame, quiet SDL."""

import os

os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
os.environ.setdefault("SDL_AUDIODRIVER", "dummy")
os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
os.environ.setdefault("XDG_RUNTIME_DIR", "/tmp")
os.environ.setdefault("MPLBACKEND", "Agg")


import pytest  # noqa: E402


@pytest.fixture
def pg():
    """pygame with its event queue (and joysticks) initialised, the queue empty."""
    from hasa_env.devices import init_pygame_input

    pygame = init_pygame_input()
    pygame.event.clear()
    yield pygame
    pygame.event.clear()
