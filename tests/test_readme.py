"""The README's Python examples run as written (in order, one namespace).

A block that starts with ``# <name>.py`` is a file the README asks the reader to
write (e.g. ``my_models.py``): it is written to the working directory, which
is on ``sys.path``, before it runs, so the blocks after it can import it.
"""

import re
import sys
from pathlib import Path

import pytest

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


@pytest.mark.slow
def test_readme_python_blocks_run(tmp_path, monkeypatch):
    pytest.importorskip("stable_baselines3")
    text = without_sections(README.read_text(), OWN_TESTS)
    blocks = re.findall(r"```python\n(.*?)```", text, re.S)
    assert len(blocks) >= 5
    run_blocks(blocks, tmp_path, monkeypatch)
    sys.modules.pop("my_models", None)
