"""The README's "Write a steering model" and "Run a study" sections run as written:
their Python blocks, then each command of their bash blocks (in this process; a command
that needs a screen must get as far as asking for one)."""

from __future__ import annotations

import re
import shlex
import shutil
import sys

import pytest
from test_readme import OWN_TESTS, README, run_blocks

from hasa_cli.bench import main as hasa_bench
from hasa_cli.drive import EXIT_NO_SCREEN
from hasa_cli.drive import main as hasa_drive
from hasa_cli.replay import main as hasa_replay

ROOT = README.parent
PROGRAMS = {"hasa-bench": hasa_bench, "hasa-drive": hasa_drive, "hasa-replay": hasa_replay}


def section(title: str) -> str:
    assert title in OWN_TESTS  # tests/test_readme.py leaves these sections to this file
    text = README.read_text()
    start = text.index(f"\n## {title}\n")
    end = text.find("\n## ", start + 1)
    return text[start : end if end > 0 else len(text)]


def commands(text: str) -> list[list[str]]:
    lines = []
    for block in re.findall(r"```bash\n(.*?)```", text, re.S):
        for line in block.splitlines():
            words = shlex.split(line, comments=True)
            if words:
                lines.append(words)
    return lines


def run(words: list[str]) -> int:
    assert words[0] in PROGRAMS, f"README command {words[0]!r} is not one of {list(PROGRAMS)}"
    return PROGRAMS[words[0]](words[1:])


@pytest.mark.slow
def test_write_a_steering_model_runs_as_written(tmp_path, monkeypatch, capsys):
    text = section("Write a steering model")
    blocks = re.findall(r"```python\n(.*?)```", text, re.S)
    assert blocks[0].startswith("# my_models.py") and len(blocks) == 2
    shutil.copytree(ROOT / "studies", tmp_path / "studies")
    run_blocks(blocks, tmp_path, monkeypatch)
    assert (tmp_path / "near_far_pd.json").exists() and len(
        list((tmp_path / "my_runs").glob("*.csv"))
    ) == 4
    lines = commands(text)
    assert len(lines) == 4
    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    for words in lines:
        code = run(words)
        needs_screen = words[:2] == ["hasa-drive", "study"] and "--synthetic" not in words
        assert code == (EXIT_NO_SCREEN if needs_screen else 0), words
    out = capsys.readouterr().out
    assert "model my_models:NearFarPD: rmse" in out and "estimator: lateral RMSE" in out
    assert "near_far_pd" in out  # ranked by hasa-bench
    sys.modules.pop("my_models", None)


@pytest.mark.slow
def test_run_a_study_runs_as_written(tmp_path, monkeypatch, capsys):
    text = section("Run a study")
    blocks = re.findall(r"```python\n(.*?)```", text, re.S)
    assert len(blocks) == 1
    shutil.copytree(ROOT / "studies", tmp_path / "studies")
    run_blocks(blocks, tmp_path, monkeypatch)
    out = capsys.readouterr().out
    assert (
        "study session P01 (pilot, complete): 3/3 measured runs, 1 practice run(s) left out" in out
    )
    (tmp_path / "recordings").symlink_to(tmp_path / "pilot")  # as if P01, P02 were people
    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    lines = commands(text)
    assert [w[:2] for w in lines] == [["hasa-drive", "study"]] * 2 + [["hasa-bench", "paper"]]
    assert run(lines[0]) == 0 and "measured   1  straight  b = +0.00 m" in capsys.readouterr().out
    assert run(lines[1]) == EXIT_NO_SCREEN and not (tmp_path / "pilot" / "P07").exists()
    assert run(lines[2]) == 0
    assert "P02     generalized" in capsys.readouterr().out
