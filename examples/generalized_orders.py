"""The generalized model with more steering lags than the paper's, to score beside it.

The paper's generalized model has two lags of the steering (na = 2). With three or four its
one-step innovations are near white and the estimator counts its lane evidence at full weight
far more often (docs/design.md §8.22). Score them against the built-ins::

    PYTHONPATH=examples hasa-bench score generalized_orders:GeneralizedNA3 \\
        generalized_orders:GeneralizedNA4

Each is fitted on the benchmark's training runs like the built-in generalized model (the
paper's other orders: nb = 4 near-point, nc = 1 far-point and nd = 2 lateral-velocity lags).
"""

from __future__ import annotations

from typing import Any

from hasa_env.steering.models import PAPER_ORDERS, GeneralizedModel

__all__ = ["GeneralizedNA3", "GeneralizedNA4"]


class GeneralizedNA3(GeneralizedModel):
    """The generalized model with three steering lags (na = 3), the paper's other orders."""

    model_type = "generalized_na3"

    def __init__(
        self,
        na: int = 3,
        nb: int = PAPER_ORDERS["nb"],
        nc: int = PAPER_ORDERS["nc"],
        nd: int = PAPER_ORDERS["nd"],
        **options: Any,
    ) -> None:
        options.setdefault("name", f"generalized-na{na}")
        super().__init__(na=na, nb=nb, nc=nc, nd=nd, **options)


class GeneralizedNA4(GeneralizedNA3):
    """The generalized model with four steering lags (na = 4), the paper's other orders."""

    model_type = "generalized_na4"

    def __init__(self, na: int = 4, **orders_and_options: Any) -> None:
        super().__init__(na=na, **orders_and_options)
