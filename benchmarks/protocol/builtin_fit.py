"""How the benchmark fits its built-in generalized model: its orders (the paper's, or by BIC on
the training runs) and its equation error's autoregression (docs/design.md §8.32); its
speed-scaled equation error is fitted on held-out residuals by
:func:`benchmarks.speed_scaled.add_speed_scaled_error` (docs/design.md §8.34), which
``hasa-replay --fit`` uses too."""

from __future__ import annotations

import warnings
from typing import Any

import pandas as pd

from hasa_env.steering import GeneralizedModel
from hasa_env.steering.order import select_order

__all__ = [
    "builtin_generalized",
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
