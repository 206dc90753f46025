"""``python -m hasa_env``: what is installed and where to start.

Prints the version, each registered environment id with its spaces and a check that it
steps (one headless step each), and the command-line programs; ``--config`` prints every
configuration key with its default and range (:func:`hasa_env.describe_config`).
Exit status 0, or 1 if an id does not make or step. A reader that closes the output early
(``python -m hasa_env | head -1``) ends it quietly (:func:`run`).
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Sequence

import gymnasium as gym

import hasa_env

PROGRAMS = (
    ("hasa-demo", "a short headless drive of every env id (smoke test)"),
    ("hasa-bench", "the paper's benchmark; 'hasa-bench score' ranks your steering model"),
    ("hasa-drive", "drive it yourself (wheel, joystick, keyboard); studies; synthetic drivers"),
    ("hasa-replay", "replay and check recordings, score models and the estimator on them"),
    ("hasa-rec", "inspect and convert recordings (Parquet, Minari)"),
)


def _space(space: gym.Space) -> str:
    """``Box(6,)``: a space's kind and shape."""
    return f"{type(space).__name__}{space.shape}"


def _check(env_id: str) -> str:
    """``"ok"`` if ``env_id`` makes, resets and steps headless, else what went wrong."""
    try:
        env = gym.make(env_id)
        try:
            env.reset(seed=0)
            env.step(env.action_space.sample())
            spaces = (
                f"action {_space(env.action_space)}, observation {_space(env.observation_space)}"
            )
        finally:
            env.close()
    except Exception as exc:  # noqa: BLE001 - reported, the other ids still checked
        return f"FAILED: {type(exc).__name__}: {exc}"
    return f"ok ({spaces})"


def main(argv: Sequence[str] | None = None) -> int:
    """Print the summary (or ``--config``); the exit status."""
    parser = argparse.ArgumentParser(
        prog="python -m hasa_env", description=__doc__.splitlines()[0], allow_abbrev=False
    )
    parser.add_argument("--version", action="version", version=f"hasa-env {hasa_env.__version__}")
    parser.add_argument("--config", action="store_true", help="print every config key")
    args = parser.parse_args(argv)
    if args.config:
        print(hasa_env.describe_config())
        return 0
    print(f"hasa-env {hasa_env.__version__}: lane keeping with ambiguous lane markings")
    print("environment ids (gym.make(id, config={...}); one step each, headless):")
    results = {env_id: _check(env_id) for env_id in hasa_env.ENV_IDS}
    for env_id, result in results.items():
        print(f"  {env_id:32s} {result}")
    print("  (the human-as-advisor ids are registered by the advisor task's package: README)")
    print("command-line programs (each with --help):")
    for name, what in PROGRAMS:
        print(f"  {name:12s} {what}")
    print("every config key: python -m hasa_env --config")
    return 0 if all(r.startswith("ok") for r in results.values()) else 1


def run(argv: Sequence[str] | None = None) -> int:
    """:func:`main`, ending quietly with status 0 when the reader closes stdout early
    (``python -m hasa_env | head -1``), as the Python docs advise (the ``signal`` module's
    note on SIGPIPE): the output is flushed inside the ``try``, and stdout then points at
    the null device so that the flush at exit does not fail again. Status 0 as the other
    ``hasa-*`` programs: the reader had what it wanted."""
    try:
        status = main(argv)
        sys.stdout.flush()
    except BrokenPipeError:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 0
    return status


if __name__ == "__main__":
    sys.exit(run())
