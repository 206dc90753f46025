"""The stress set: deliberately bad advisors the estimator must not trust blindly.

``hasa-bench paper --stress`` scores these beside the real models, on the
same runs, so anyone can see what the estimator does with a bad steering
model (docs/design.md §9.8). Each is a generalized (ARX) model of the
paper's orders fitted on the seed's training run, then spoiled:

| name | what it is |
|------|------------|
| ``stress_no_lane_info`` | the fit with every bearing coefficient (b, c) set to 0: it predicts steering from its own past and v_y only, so it cannot tell lanes apart |
| ``stress_sign_flipped`` | the fit with the bearing and v_y coefficients (b, c, d) negated: it expects the driver to steer away from the lane centre |
| ``stress_random_arx`` | a random stable ARX model: AR poles drawn with radius 0.3-0.95, each b, c, d coefficient drawn from a normal with the fitted block's RMS (seeded by the training run) |
| ``stress_unregularized`` | plain least squares (no ridge, no stability check) on a constant-speed run of the training driver: a collinear fit (flagged ``collinear_features`` on all 15 seeds measured, 0-4 and 25-34), unstable on 2 of them (seeds 0 and 3: an AR pole at 1.003-1.008), and whose lane terms can point either way while it predicts the steering well |

What a good estimator does with them: it ends no run confidently (> 0.95)
in the wrong lane, and its lateral RMSE stays near the no-steering
baseline's (the steering channel is then worth nothing, but costs nothing).
Each is also put in the driver's seat first (the benchmark's lane-keeping
check, :func:`benchmarks.protocol.models.check_lane_keeping`): the
sign-flipped model leaves the road within seconds on every seed measured,
and a model that does gives the estimator no lane evidence.
"""

from __future__ import annotations

import zlib
from abc import abstractmethod
from typing import Any

import numpy as np
import pandas as pd

from hasa_env.steering import GeneralizedModel

__all__ = [
    "STRESS_MODELS",
    "NoLaneInformation",
    "RandomStableARX",
    "SignFlipped",
    "UnregularizedConstantSpeed",
    "stress_models",
]


class _SpoiledFit(GeneralizedModel):
    """A generalized model fitted as usual, then spoiled by :meth:`spoil`."""

    training = "training_run"
    """Which run it is fitted on: "training_run" or "constant_speed" (the protocol supplies it)."""

    def fit(self, runs: Any, road: Any = None, **options: Any) -> GeneralizedModel:
        fitted = super().fit(runs, road=road, **options)
        coefficients = {
            k: np.asarray(v, dtype=np.float64) for k, v in fitted.coefficients().items()
        }
        spoiled = self.spoil(coefficients, runs)
        return fitted.with_parameters(np.concatenate([spoiled[k] for k in "abcd"]))

    @abstractmethod
    def spoil(self, coefficients: dict[str, np.ndarray], runs: Any) -> dict[str, np.ndarray]:
        """The spoiled coefficient blocks {"a", "b", "c", "d"} of the fit on ``runs``."""


class NoLaneInformation(_SpoiledFit):
    """The fit without its bearing terms (b = c = 0): no lane information."""

    model_type = "stress_no_lane_info"

    def spoil(self, coefficients: dict[str, np.ndarray], runs: Any) -> dict[str, np.ndarray]:
        return coefficients | {"b": 0.0 * coefficients["b"], "c": 0.0 * coefficients["c"]}


class SignFlipped(_SpoiledFit):
    """The fit with its lane terms (b, c, d) negated."""

    model_type = "stress_sign_flipped"

    def spoil(self, coefficients: dict[str, np.ndarray], runs: Any) -> dict[str, np.ndarray]:
        return coefficients | {k: -coefficients[k] for k in "bcd"}


class RandomStableARX(_SpoiledFit):
    """A random stable ARX model with the fitted model's coefficient magnitudes."""

    model_type = "stress_random_arx"

    def spoil(self, coefficients: dict[str, np.ndarray], runs: Any) -> dict[str, np.ndarray]:
        frames = [runs] if isinstance(runs, pd.DataFrame) else list(runs)
        digest = zlib.crc32(
            np.ascontiguousarray(frames[0]["steering"].to_numpy(dtype=np.float64)).tobytes()
        )
        rng = np.random.default_rng([digest, 0x57E55])
        n_a = coefficients["a"].size
        radius = rng.uniform(0.3, 0.95, size=n_a)
        angle = rng.uniform(0.0, np.pi, size=n_a)
        roots = radius * np.exp(1j * angle)
        if n_a >= 2:  # a complex pair keeps the polynomial real
            roots[1] = np.conj(roots[0])
            if n_a > 2:
                roots[2:] = radius[2:] * rng.choice([-1.0, 1.0], size=n_a - 2)
        elif n_a == 1:
            roots = radius * rng.choice([-1.0, 1.0], size=1)
        # delta(k) = sum a_j delta(k-j): the roots of z^n - a_1 z^(n-1) - ... - a_n
        a = -np.real(np.poly(roots))[1:] if n_a else np.zeros(0)
        out = {"a": a}
        for key in "bcd":
            block = coefficients[key]
            scale = float(np.sqrt(np.mean(block * block))) if block.size else 0.0
            out[key] = rng.normal(0.0, scale, size=block.size)
        return out


class UnregularizedConstantSpeed(GeneralizedModel):
    """Least squares without ridge or stability check on a constant-speed run."""

    model_type = "stress_unregularized"
    training = "constant_speed"

    def fit(self, runs: Any, road: Any = None, **options: Any) -> GeneralizedModel:
        options = options | {"ridge": 0.0, "stable": False}
        return super().fit(runs, road=road, **options)


STRESS_MODELS: dict[str, type[GeneralizedModel]] = {
    "stress_no_lane_info": NoLaneInformation,
    "stress_sign_flipped": SignFlipped,
    "stress_random_arx": RandomStableARX,
    "stress_unregularized": UnregularizedConstantSpeed,
}
"""The stress set by result name."""


def stress_models() -> list[tuple[str, GeneralizedModel]]:
    """(name, unfitted model) of every stress model, in :data:`STRESS_MODELS` order."""
    return [(name, cls(name=name)) for name, cls in STRESS_MODELS.items()]
