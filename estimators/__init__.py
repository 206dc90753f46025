"""State estimation with the human as advisor (paper section 4, docs/design.md §8).

- :class:`GaussianMixtureEKF`: one EKF per lane hypothesis, the human's
  steering entering through any ARX steering model
  (:class:`~hasa_env.steering.arx.ARXForm`); vectorized over hypotheses and
  over many runs at once (:mod:`~estimators.gm_ekf`); its
  :class:`FilterSettings` (:mod:`~estimators.settings`) and
  :class:`FilterMatrices` (:mod:`~estimators.filter_matrices`).
- :class:`ARXStateSpace`: the augmented state [v_x, y, v_y, b, m_1..m_n] of a
  car and an ARX steering model, with exact Jacobians.
- Baselines: :class:`NoSteeringEKF`, :class:`SingleHypothesisEKF`,
  :class:`OracleEKF`, the steering-free lane-centring prior
  :class:`LaneCentringEKF` (fitted by :func:`fit_lane_centring`), and :class:`FilterpyGMEKF` (filterpy reference).
- :func:`run_estimator`: filter recordings offline, batched (:func:`stack_recordings`:
  stacked once for several estimators).
- Gymnasium wrappers: :class:`EstimatorInfoWrapper`,
  :class:`EstimatorObservationWrapper` (single and vector envs).

The human-as-advisor task (an env with a human and this package's estimator in the
loop) is the layer above: :mod:`advisor_tasks`.
"""

from estimators.arx_state_space import MEASUREMENT_NAMES, PHYSICAL_STATE_NAMES, ARXStateSpace
from estimators.base import (
    ACCELERATION_KEYS,
    MEASUREMENT_KEYS,
    Estimate,
    LaneEstimator,
    inputs_from_info,
    measurements_from_info,
)
from estimators.baselines import NoSteeringEKF, OracleEKF, SingleHypothesisEKF
from estimators.calibration import (
    expected_calibration_error,
    lane_calibration_bins,
    steering_channel_shares,
    steering_live_share,
)
from estimators.filter_matrices import FilterMatrices
from estimators.gm_ekf import GaussianMixtureEKF
from estimators.lane_centring import LaneCentringEKF, LaneCentringParams, fit_lane_centring
from estimators.offline import EstimationResult, hypotheses_of, run_estimator, stack_recordings
from estimators.settings import FilterSettings
from estimators.tuning import PredictionCheck, prediction_check, steering_residual_std
from estimators.wrappers import (
    EstimatorInfoWrapper,
    EstimatorObservationWrapper,
    VectorEstimatorInfoWrapper,
    VectorEstimatorObservationWrapper,
    estimate_info_keys,
    estimate_observation_names,
)
from hasa_env._lazy import lazy_attributes

__all__ = [
    "ACCELERATION_KEYS",
    "ARXStateSpace",
    "Estimate",
    "EstimationResult",
    "expected_calibration_error",
    "lane_calibration_bins",
    "steering_channel_shares",
    "steering_live_share",
    "EstimatorInfoWrapper",
    "EstimatorObservationWrapper",
    "FilterMatrices",
    "FilterSettings",
    "FilterpyGMEKF",  # noqa: F822 - a lazy attribute (see below)
    "GaussianMixtureEKF",
    "LaneCentringEKF",
    "LaneCentringParams",
    "LaneEstimator",
    "MEASUREMENT_KEYS",
    "MEASUREMENT_NAMES",
    "NoSteeringEKF",
    "OracleEKF",
    "PHYSICAL_STATE_NAMES",
    "SingleHypothesisEKF",
    "VectorEstimatorInfoWrapper",
    "VectorEstimatorObservationWrapper",
    "estimate_info_keys",
    "estimate_observation_names",
    "fit_lane_centring",
    "hypotheses_of",
    "inputs_from_info",
    "measurements_from_info",
    "run_estimator",
    "stack_recordings",
    "steering_residual_std",
    "PredictionCheck",
    "prediction_check",
]


# loaded on first access: the filterpy reference filter imports filterpy (and with it
# scipy.stats, about a second)
_LAZY = {"FilterpyGMEKF": "estimators.filterpy_ekf"}
__getattr__, __dir__ = lazy_attributes(
    __name__, _LAZY, eager=[n for n in __all__ if n not in _LAZY]
)
