"""Write your own steering model, fit it, score it, save it, and drive with it.

A steering model is a subclass of :class:`hasa_env.steering.SteeringModel`.
If it is linear in its parameters it implements four things and inherits the
rest (least-squares fitting with standard errors, scoring, free run, JSON
files, driving through :class:`hasa_env.drivers.ModelDriver`):

- ``model_type``: the name of its type in model files;
- ``parameter_names``;
- ``regressors``: which features (delta, phi, omega, lateral_velocity,
  speed) it uses at which lags;
- ``design(features)``: its equation over a run,
  ``delta(k) = offset(k) + matrix(k, :) @ parameters``;

and, if it is an ARX model (so the estimator can use it), ``arx()``.

The model below is a near/far-point PD controller with memory (an ARX model)::

    delta(k) = m delta(k-1) + k_p phi(k) + k_d [phi(k) - phi(k-1)] + k_f Omega(k)

Run:  python examples/custom_steering_model.py
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

from hasa_env.drivers import ModelDriver, population, run_driver, run_population
from hasa_env.steering import (
    ARXForm,
    Design,
    GeneralizedModel,
    Regressor,
    SteeringModel,
    TwoPointModel,
    check_identifiability,
    lagged,
    score,
)


class NearFarPD(SteeringModel):
    """delta(k) = m delta(k-1) + k_p phi(k) + k_d [phi(k) - phi(k-1)] + k_f Omega(k).

    Parameters: ``memory`` m (1), ``proportional`` k_p, ``derivative`` k_d and
    ``far`` k_f (rad/rad).
    """

    model_type = "near_far_pd"

    @property
    def parameter_names(self) -> tuple[str, ...]:
        return ("memory", "proportional", "derivative", "far")

    @property
    def regressors(self) -> tuple[Regressor, ...]:
        return (
            Regressor("delta", 1),
            Regressor("phi", 0),
            Regressor("phi", 1),
            Regressor("omega", 0),
        )

    def design(self, features: pd.DataFrame) -> Design:
        delta = features["delta"].to_numpy(dtype=float)
        phi = features["phi"].to_numpy(dtype=float)
        omega = features["omega"].to_numpy(dtype=float)
        matrix = np.column_stack([lagged(delta, 1), phi, phi - lagged(phi, 1), omega])
        return Design(target=delta, offset=np.zeros_like(delta), matrix=matrix)

    def arx(self) -> ARXForm | None:
        if not self.is_fitted:
            return None
        m, k_p, k_d, k_f = self.parameter_vector.tolist()
        return ARXForm(
            a=(m,),
            b=(k_p + k_d, -k_d),
            c=(k_f,),
            near_distance=self.near_distance,
            far_distance=self.far_distance,
            dt=self.dt,
        )


def main() -> None:
    drivers = population("paper", seed=0)
    runs = run_population(drivers[:4], runs=3, seed=0)
    training, validation = runs["Ill"][0], [r for name in ("1", "2", "3") for r in runs[name]]

    # 1. fit (least squares with standard errors) on one run
    mine = NearFarPD().fit(training)
    print(mine)
    print(mine.fit_result.summary().to_string(float_format=lambda x: f"{x: .4g}"))
    print(check_identifiability(mine).message, "\n")

    # 2. score it next to the paper's models (one step ahead, measured past steering)
    print(f"{'model':<12} {'RMSE (rad)':>11} {'R^2':>8} {'R^2 inc':>8}")
    for model in (mine, TwoPointModel().fit(training), GeneralizedModel().fit(training)):
        s = score(model, validation, free_run=False)
        print(f"{model.name:<12} {s['rmse']:11.3e} {s['r2']:8.4f} {s['r2_increments']:8.3f}")

    # 3. save and load it (the class must be defined/imported before loading)
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "near_far_pd.json"
        mine.save(path)
        loaded = SteeringModel.load(path)
        assert loaded == mine and isinstance(loaded, NearFarPD)
        print(f"\nsaved and loaded {path.name}: {len(path.read_text())} bytes, identical model")

    # 4. drive with it: the model plus a little noise becomes a driver
    driver = ModelDriver(mine, noise_std=1e-5, name="near-far PD")
    frame = run_driver(driver, seed=1, options={"bias_index": 0})[0]
    y = frame["lateral_offset"].to_numpy()
    print(
        f"driving with it from y = {y[0]:.2f} m: |y| = {abs(y[-1]):.3f} m after 30 s, "
        f"left the road: {bool(frame['terminated'].any())}"
    )


if __name__ == "__main__":
    main()
