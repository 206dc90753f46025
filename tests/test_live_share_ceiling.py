"""examples/live_share_ceiling.py (docs/design.md §8.20) runs and gives a share per driver."""

from __future__ import annotations

import importlib.util
from pathlib import Path

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "live_share_ceiling.py"


def test_the_ceiling_example_gives_one_live_share_per_driver() -> None:
    spec = importlib.util.spec_from_file_location("live_share_ceiling", EXAMPLE)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    table = module.main(["--seeds", "7000", "--drivers", "2", "--runs", "2", "--duration", "6"])
    assert list(table["driver"]) == ["Ill", "1"]
    assert table["live"].between(0.0, 1.0).all()
    assert (table["tau_median"] >= 1.0).all()  # the evidence scale never amplifies
    assert (table["lambda_median"] > 0).all() and (table["lateral_rmse"] > 0).all()
