"""examples/generalized_orders.py (docs/design.md §8.22): the generalized model with three and
four steering lags fits, saves, loads and is scored by ``hasa-bench score`` beside the
built-ins."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

from hasa_cli.bench import main
from hasa_env.drivers import SyntheticDriver, population, run_driver
from hasa_env.steering import SteeringModel

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
TINY = ["--seed", "0", "--population", "paper-pi", "--drivers", "2", "--runs", "1",
        "--ill-runs", "2", "--duration", "4", "--curved-runs", "0", "--training-drivers", "1",
        "--no-plots", "--quiet", "--model-time-limit", "0"]  # fmt: skip


@pytest.fixture
def orders_module(monkeypatch: pytest.MonkeyPatch):  # noqa: ANN201
    monkeypatch.syspath_prepend(str(EXAMPLES))
    import generalized_orders

    yield generalized_orders
    sys.modules.pop("generalized_orders", None)


def test_the_longer_autoregressions_fit_save_and_load(orders_module, tmp_path: Path) -> None:
    run = run_driver(SyntheticDriver(population("paper", 0, 1)[0]), runs=1, seed=3)[0]
    for cls, na in ((orders_module.GeneralizedNA3, 3), (orders_module.GeneralizedNA4, 4)):
        model = cls().fit(run)
        assert model.orders == {"na": na, "nb": 4, "nc": 1, "nd": 2}
        assert model.arx() is not None and model.name == f"generalized-na{na}"
        model.save(tmp_path / f"na{na}.json")
        loaded = SteeringModel.load(tmp_path / f"na{na}.json")
        assert type(loaded) is cls and loaded.orders == model.orders


def test_hasa_bench_scores_them_beside_the_built_ins(orders_module, tmp_path: Path) -> None:
    specs = ["generalized_orders:GeneralizedNA3", "generalized_orders:GeneralizedNA4"]
    assert main(["score", *specs, *TINY, "--out", str(tmp_path)]) == 0
    doc = json.loads((tmp_path / "results.json").read_text())
    scored = {row["model"] for row in doc["summary"]}
    assert {"generalized", "generalized-na3", "generalized-na4"} <= scored  # by their names
    assert not doc["errors"]
