"""The built-in generalized model's orders (docs/design.md §8.26): selected by BIC on the
training runs on request (``generalized_orders = "bic"``), the paper's by default."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from benchmarks.protocol import BenchmarkError, ProtocolConfig
from benchmarks.protocol.builtin_fit import with_selected_orders
from hasa_cli.bench import main
from hasa_env.drivers import SyntheticDriver, population, run_driver
from hasa_env.steering import GeneralizedModel
from hasa_env.steering.models import PAPER_ORDERS
from hasa_env.steering.order import select_order

TINY = ["--seed", "0", "--population", "paper-pi", "--drivers", "2", "--runs", "1",
        "--ill-runs", "2", "--duration", "6", "--curved-runs", "0", "--training-drivers", "1",
        "--no-plots", "--quiet"]  # fmt: skip
ORDER_KEYS = ("na", "nb", "nc", "nd")


def test_the_default_keeps_the_papers_orders_and_other_choices_are_refused_by_name() -> None:
    assert ProtocolConfig().generalized_orders == "paper"
    with pytest.raises(BenchmarkError, match=r"generalized_orders.*'paper', 'bic'"):
        ProtocolConfig(generalized_orders="aic")


def test_the_selection_is_select_order_on_the_training_runs_and_keeps_the_model_options() -> None:
    params = population("paper-pi", 0, 2)
    runs = [run_driver(SyntheticDriver(p), runs=1, seed=3, config={"time_limit": 4.0})[0]
            for p in params]  # fmt: skip
    base = GeneralizedModel(near_distance=6.0, far_distance=20.0, decision_lag=2)
    chosen, info = with_selected_orders(base, runs)
    expected = select_order(runs, near_distance=6.0, far_distance=20.0, decision_lag=2).orders
    assert chosen.structure() == expected == info["orders"]
    assert info["criterion"] == "bic" and info["candidates"] == 4 * 6 * 4 * 4
    assert 0 < info["n_common"] <= sum(len(r) for r in runs)
    assert (chosen.near_distance, chosen.far_distance, chosen.decision_lag) == (6.0, 20.0, 2)
    assert chosen.name == base.name and not chosen.is_fitted


def _generalized(folder: Path) -> dict:
    doc = json.loads((folder / "results.json").read_text())
    return doc, next(m for m in doc["models"] if m["name"] == "generalized")


def test_the_benchmark_fits_the_selected_orders_and_says_so(tmp_path: Path) -> None:
    bic, paper = tmp_path / "bic", tmp_path / "paper"
    assert main(["paper", *TINY, "--generalized-orders", "bic", "--out", str(bic)]) == 0
    assert main(["paper", *TINY, "--out", str(paper)]) == 0
    doc, model = _generalized(bic)
    assert doc["config"]["generalized_orders"] == "bic"
    orders = model["order_selection"]["orders"]
    assert {k: v for k, v in model["structure"].items() if k in orders} == orders
    assert len(model["parameters"]) == sum(orders[k] for k in ORDER_KEYS)
    shown = ", ".join(str(orders[k]) for k in ORDER_KEYS)
    assert (
        f"generalized orders (na, nb, nc, nd) by BIC on them: ({shown}) on seed 0"
        in (bic / "report.md").read_text()
    )
    doc, model = _generalized(paper)
    assert doc["config"]["generalized_orders"] == "paper"
    assert model["structure"] == PAPER_ORDERS | {"equation_error_order": 2}
    assert "order_selection" not in model
    assert "generalized orders" not in (paper / "report.md").read_text()
