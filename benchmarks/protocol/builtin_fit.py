"""How the benchmark fits its built-in generalized model: its orders (the paper's, or by BIC on
the training runs), its equation error's autoregression (docs/design.md §8.32) and its
speed-scaled equation error, fitted on held-out residuals (docs/design.md §8.34)."""

from __future__ import annotations

import copy
import functools
import warnings
from typing import Any

import pandas as pd

from estimators.tuning import held_out_speed_scaled_error, speed_scaled_gain
from hasa_env.steering import GeneralizedModel, SteeringModel
from hasa_env.steering.order import select_order

__all__ = [
    "add_speed_scaled_error",
    "builtin_generalized",
    "speed_scaled_description",
    "with_selected_orders",
]


def builtin_generalized(
    model: GeneralizedModel,
    train: pd.DataFrame | list[pd.DataFrame],
    generalized_orders: str,
    equation_error_order: int,
    info: dict[str, Any],
) -> GeneralizedModel:
    """The built-in generalized model to fit: its orders selected by BIC on ``train``
    (``generalized_orders == "bic"``, what was selected in ``info["order_selection"]``) or
    kept, with ``equation_error_order`` lags of its equation error's autoregression."""
    if generalized_orders == "bic":
        model, info["order_selection"] = with_selected_orders(model, train)
    structure = model.structure() | {"equation_error_order": equation_error_order}
    return GeneralizedModel(**structure, **model.common_kwargs())


def with_selected_orders(
    model: GeneralizedModel, train: pd.DataFrame | list[pd.DataFrame]
) -> tuple[GeneralizedModel, dict[str, Any]]:
    """``model`` (unfitted) with its orders (na, nb, nc, nd) selected by BIC on the training
    runs ``train`` (:func:`hasa_env.steering.order.select_order` with its default grid, from
    (1, 1, 0, 0) to (4, 6, 3, 3), every candidate on one common sample; docs/design.md
    §8.26), and what was selected: ``orders``, ``criterion``, ``n_common`` (samples) and
    the ``candidates`` compared. The selection sees the training runs only."""
    options = {k: v for k, v in model.common_kwargs().items() if k != "name"}
    with warnings.catch_warnings():  # the candidates' fits: the chosen one is fitted (and
        warnings.simplefilter("ignore")  # its warnings reported) by _fit_one
        selection = select_order(train, **options)
    chosen = GeneralizedModel(**selection.orders, **model.common_kwargs())
    return chosen, {
        "orders": dict(selection.orders),
        "criterion": selection.criterion,
        "n_common": int(selection.n_common),
        "candidates": len(selection.table),
    }


def add_speed_scaled_error(
    model: GeneralizedModel,
    fitted: GeneralizedModel,
    runs: list[pd.DataFrame],
    sensor_std: float,
    info: dict[str, Any],
) -> None:
    """Give the built-in generalized model ``fitted`` (``model`` fitted on ``runs``) its
    speed-scaled equation error, fitted on held-out residuals (each run's from the model
    refitted on the others; :func:`estimators.tuning.held_out_speed_scaled_error`), and record
    in ``info`` the error (``speed_scaled_error``), whether it was held out
    (``speed_scaled_held_out``) and its gain over one white level on ``runs``
    (``speed_scaled_gain``, what the trust rule reads)."""
    found, info["speed_scaled_held_out"] = held_out_speed_scaled_error(
        fitted, runs, functools.partial(_refit, model, sensor_std=sensor_std)
    )
    fitted.equation_error_speed_scaled = found
    info["speed_scaled_error"] = speed_scaled_description(fitted)
    info["speed_scaled_gain"] = speed_scaled_gain(fitted, runs)


def _refit(model: GeneralizedModel, runs: list[pd.DataFrame], *, sensor_std: float) -> Any:
    """``model`` fitted on ``runs`` as :func:`_fit_one` fits it, its warnings not shown (they
    are the fit's own, reported once)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return copy.deepcopy(model).fit(runs, sensor_std=sensor_std)


def speed_scaled_description(fitted: SteeringModel) -> dict[str, float] | None:
    """The model's speed-scaled equation error (docs/design.md §8.34) as numbers; None: none."""
    found = getattr(fitted, "equation_error_speed_scaled", None)
    return None if found is None else found.to_dict()
