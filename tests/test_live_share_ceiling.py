"""examples/live_share_ceiling.py (docs/design.md §8.20, §8.22) runs and gives a share per
driver, for the paper's steering autoregression and a longer one."""

from __future__ import annotations

from types import ModuleType

import pytest
from _programs import load_example


def _example() -> ModuleType:
    return load_example("live_share_ceiling")


def test_the_ceiling_example_gives_one_live_share_per_driver() -> None:
    module = _example()
    table = module.main(["--seeds", "7000", "--drivers", "2", "--runs", "2", "--duration", "6"])
    assert list(table["driver"]) == ["Ill", "1"]
    assert table["live"].between(0.0, 1.0).all()
    assert (table["tau_median"] >= 1.0).all()  # the evidence scale never amplifies
    assert (table["lambda_median"] > 0).all() and (table["lateral_rmse"] > 0).all()
    slow, fast = table["lambda_below_25"], table["lambda_above_35"]
    assert ((slow > 0) | slow.isna()).all() and ((fast > 0) | fast.isna()).all()


def test_the_ceiling_example_fits_the_autoregression_it_is_given(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    module = _example()
    fitted = []
    real = module.GeneralizedModel

    def recording(**orders):  # the model the example builds, recorded
        fitted.append(orders)
        return real(**orders)

    monkeypatch.setattr(module, "GeneralizedModel", recording)
    args = ["--seeds", "7000", "--drivers", "1", "--runs", "2", "--duration", "6", "--na", "3"]
    table = module.main(args)
    assert fitted == [{"na": 3}] and len(table) == 1
