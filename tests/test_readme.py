"""The README's Python examples run as written, each block alone in a fresh process.

A block that starts with ``# <name>.py`` is a file the README asks the reader to
write (e.g. ``my_models.py``): it is written to the working directory of the
blocks after it, so they can import it.
"""

import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from _programs import program_env, run_program

README = Path(__file__).resolve().parents[1] / "README.md"
FILE_BLOCK = re.compile(r"# ([A-Za-z_][A-Za-z0-9_]*\.py)\n")
OWN_TESTS = ("Write a steering model", "Run a study")
"""Sections whose blocks tests/test_readme_sections.py runs, with their commands."""


def without_sections(text: str, titles: tuple[str, ...]) -> str:
    """``text`` without the ``## <title>`` sections named."""
    for title in titles:
        start = text.index(f"\n## {title}\n")
        end = text.find("\n## ", start + 1)
        text = text[:start] + (text[end:] if end > 0 else "\n")
    return text


def run_blocks(blocks: list[str], folder: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Run README python blocks in ``folder`` in one namespace (files written where asked)."""
    monkeypatch.chdir(folder)  # the examples write recordings/ relative to the working directory
    monkeypatch.syspath_prepend(str(folder))
    namespace: dict = {}
    for i, block in enumerate(blocks):
        match = FILE_BLOCK.match(block)
        if match:
            (folder / match.group(1)).write_text(block)
        try:
            exec(compile(block, f"README.md python block {i + 1}", "exec"), namespace)
        except Exception as exc:  # pragma: no cover - the message is the point
            pytest.fail(f"README python block {i + 1} failed: {exc!r}\n{block}")


def python_blocks(text: str) -> list[str]:
    """The ```python blocks of ``text``."""
    return re.findall(r"```python\n(.*?)```", text, re.S)


@pytest.mark.slow
def test_each_readme_python_block_runs_alone_in_a_fresh_process(tmp_path):
    """A reader copies one block into a file and runs it: no block may lean on another's
    names. Each runs as ``python block.py`` in a folder of its own (a ``# <name>.py`` block
    is also left there as that file, for the blocks that import it)."""
    pytest.importorskip("stable_baselines3")
    blocks = python_blocks(without_sections(README.read_text(), OWN_TESTS))
    assert len(blocks) >= 5
    modules: dict[str, str] = {}
    failures = []
    for i, block in enumerate(blocks, start=1):
        folder = tmp_path / f"block_{i}"
        folder.mkdir()
        for name, text in modules.items():
            (folder / name).write_text(text)
        match = FILE_BLOCK.match(block)
        if match:
            modules[match.group(1)] = block
        (folder / "block.py").write_text(block)
        done = subprocess.run(
            [sys.executable, "block.py"],
            cwd=folder,
            env=program_env(),
            capture_output=True,
            text=True,
            timeout=600,
        )
        if done.returncode != 0:
            failures.append(f"README python block {i} failed:\n{block}\n{done.stderr[-2000:]}")
    assert not failures, "\n\n".join(failures)


@pytest.mark.slow
def test_the_offline_dataset_commands_run_in_a_fresh_clone_folder(tmp_path):
    """The "Offline datasets" commands, each as a user types it in a folder holding only the
    repository's shipped recordings (no study run before)."""
    pytest.importorskip("minari")
    pytest.importorskip("pyarrow")
    start = README.read_text().index("\n## Offline datasets\n")
    block = re.search(r"```bash\n(.*?)```", README.read_text()[start:], re.S)
    assert block is not None
    shutil.copytree(README.parent / "recordings", tmp_path / "recordings")
    lines = [shlex.split(line, comments=True) for line in block.group(1).splitlines()]
    lines = [words for words in lines if words]
    assert [words[:2] for words in lines] == [
        ["hasa-rec", "info"], ["hasa-rec", "convert"], ["hasa-rec", "export-minari"]
    ]  # fmt: skip
    for words in lines:
        done = run_program(words[0], *words[1:], cwd=tmp_path)
        assert done.returncode == 0, f"{shlex.join(words)}: {done.stderr}"
    assert list((tmp_path / "parquet").glob("*.parquet"))
    assert (tmp_path / "datasets" / "hasa" / "drives-v0").is_dir()
