"""Order selection of the generalized model: BIC (or AIC) on a common sample
(the paper's future work 1; docs/design.md §6.2).

Every candidate is fitted the way :func:`hasa_env.steering.fitting.fit_model`
fits: ridge on standardized columns, with the penalty chosen once by blocked
cross-validation of the largest candidate on the common sample (or given),
and the criteria count the effective number of parameters
``df = trace(hat matrix)``::

    BIC = n log(RSS / n) + df log(n)        AIC = n log(RSS / n) + 2 df
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from hasa_env.sim.road import Road
from hasa_env.steering.design import as_runs
from hasa_env.steering.fitting import (
    DEFAULT_LAMBDAS,
    choose_ridge_lambda,
    criteria,
    design_blocks,
    ridge_regression,
)
from hasa_env.steering.models import GeneralizedModel

__all__ = ["OrderSelection", "select_order"]


@dataclass(frozen=True)
class OrderSelection:
    """Result of :func:`select_order`.

    Attributes:
        orders: the selected orders {"na", "nb", "nc", "nd"}.
        criterion: "bic" or "aic".
        table: every candidate (orders, n_params, rss, aic, bic), best first.
        n_common: samples of the common estimation sample.
        model: a :class:`~hasa_env.steering.models.GeneralizedModel` of the
            selected orders fitted on all the data (not only the common sample)
            with the same penalty.
        ridge_lambda: the penalty every candidate was fitted with.
    """

    orders: dict[str, int]
    criterion: str
    table: pd.DataFrame
    n_common: int
    model: GeneralizedModel
    ridge_lambda: float = 0.0


def _order_grid(
    value: Mapping[str, int] | Sequence[int] | None, default: Sequence[int], label: str
) -> tuple[int, ...]:
    keys = ("na", "nb", "nc", "nd")
    if value is None:
        return tuple(default)
    if isinstance(value, Mapping):
        unknown = [k for k in value if k not in keys]
        if unknown:
            raise ValueError(f"{label}: unknown key {unknown[0]!r}; allowed: {', '.join(keys)}")
        merged = dict(zip(keys, default, strict=True))
        merged.update(value)
        out = tuple(merged[k] for k in keys)
    else:
        out = tuple(value)
        if len(out) != 4:
            raise ValueError(f"{label} must give 4 orders (na, nb, nc, nd), got {out}")
    for k, v in zip(keys, out, strict=True):
        if isinstance(v, bool) or not isinstance(v, int | np.integer) or v < 0:
            raise ValueError(f"{label}[{k!r}] must be a non-negative integer, got {v!r}")
    return tuple(int(v) for v in out)


def select_order(
    runs: pd.DataFrame | Sequence[pd.DataFrame],
    max_orders: Mapping[str, int] | Sequence[int] | None = None,
    min_orders: Mapping[str, int] | Sequence[int] | None = None,
    criterion: str = "bic",
    road: Road | None = None,
    *,
    ridge: str | float = "cv",
    **model_kwargs: Any,
) -> OrderSelection:
    """Search the generalized model's orders by BIC (or AIC) on a common sample.

    Every candidate (na, nb, nc, nd) between ``min_orders`` (default
    (1, 1, 0, 0)) and ``max_orders`` (default (4, 6, 3, 3)) is fitted on the
    *same* samples: those where the largest model has its full history, so the
    criteria compare like with like (see the module docstring).

    Args:
        runs: one run or a list of runs.
        max_orders, min_orders: mappings {"na", "nb", "nc", "nd"} or 4-sequences.
        criterion: "bic" or "aic".
        road: the road of the runs (None: from their metadata, else straight).
        ridge: "cv" (the penalty from blocked cross-validation of the largest
            candidate), a relative penalty, or 0 (least squares).
        **model_kwargs: options of the models (near_distance, far_distance, dt, ...).
    """
    if criterion not in ("bic", "aic"):
        raise ValueError(f"criterion must be 'bic' or 'aic', got {criterion!r}")
    high = _order_grid(max_orders, (4, 6, 3, 3), "max_orders")
    low = _order_grid(min_orders, (1, 1, 0, 0), "min_orders")
    if any(lo > hi for lo, hi in zip(low, high, strict=True)):
        raise ValueError(f"min_orders {low} exceed max_orders {high}")
    frames = as_runs(runs)
    largest = GeneralizedModel(*high, **model_kwargs)
    blocks = design_blocks(largest, frames, road)
    X = np.vstack([b["matrix"] for b in blocks])
    y = np.concatenate([b["target"] for b in blocks])
    n = y.size
    if isinstance(ridge, str):
        if ridge != "cv":
            raise ValueError(f"ridge must be 'cv' or a number >= 0, got {ridge!r}")
        cv = choose_ridge_lambda(
            [(b["matrix"], b["target"]) for b in blocks], DEFAULT_LAMBDAS, gap=largest.max_lag
        )
        ridge_lambda = cv.ridge_lambda
    else:
        ridge_lambda = float(ridge)
    offsets = np.cumsum([0, *high])  # column blocks a | b | c | d of the largest design
    rows = []
    for orders in itertools.product(*(range(lo, hi + 1) for lo, hi in zip(low, high, strict=True))):
        cols = [offsets[block] + i for block, order in enumerate(orders) for i in range(order)]
        p = len(cols)
        if p >= n:
            continue
        if p == 0:
            rss, df = float(y @ y), 0.0
        else:
            try:
                solution = ridge_regression(X[:, cols], y, ridge_lambda)
            except ValueError:
                continue  # a collinear candidate without a penalty: not estimable
            rss, df = solution.rss, solution.effective_parameters
        _, aic, bic = criteria(rss, n, df)
        rows.append({"na": orders[0], "nb": orders[1], "nc": orders[2], "nd": orders[3],
                     "n_params": p, "effective_parameters": df, "rss": rss, "aic": aic,
                     "bic": bic})  # fmt: skip
    if not rows:
        raise ValueError("no candidate order could be fitted on these data")
    table = (
        pd.DataFrame(rows)
        .sort_values([criterion, "n_params"], kind="stable")
        .reset_index(drop=True)
    )
    best = {k: int(table[k].to_numpy()[0]) for k in ("na", "nb", "nc", "nd")}
    model = GeneralizedModel(**best, **model_kwargs).fit(frames, road=road, ridge=ridge_lambda)
    return OrderSelection(best, criterion, table, n, model, ridge_lambda)
