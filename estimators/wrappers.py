"""Gymnasium wrappers that run an estimator alongside a hasa env.

- :class:`EstimatorInfoWrapper`: adds the estimate to ``info`` at ``reset``
  and every ``step`` (always the same keys, :func:`estimate_info_keys`).
- :class:`EstimatorObservationWrapper`: replaces the observation with the
  estimate, a ``Box`` for RL agents (:func:`estimate_observation_names`),
  and also adds the info keys.

Both accept a single env (``gym.make``) or a vector env (the native one of
``gym.make_vec(..., vectorization_mode="vector_entry_point")`` or gymnasium's
sync/async ones); given a vector env they return the vector versions
:class:`VectorEstimatorInfoWrapper` / :class:`VectorEstimatorObservationWrapper`
(``gymnasium.vector.VectorWrapper``), which filter all cars in one batch and
re-initialise a car's slot when the env autoresets it (``NEXT_STEP`` or
``SAME_STEP`` autoreset).

The estimator needs what a car's computer has: the speed, the biased camera
and the IMU, plus the human's steering. In an env the steering sensor reads
the applied steering, which is the human's when a human (or a synthetic
driver) drives, so the wrappers read ``info``'s ``sensor_*`` keys. The lane
hypotheses and their prior come from the env's config
(``markings.hypotheses``, ``markings.probabilities``). The oracle baseline
gets the true bias from ``info["bias"]``.

Example::

    env = gym.make("hasa_env/LaneKeeping-v0", config={"action": {"type": "physical"}})
    ekf = GaussianMixtureEKF(
        GeneralizedModel.paper().arx(),
        FilterSettings.from_env_config(env.unwrapped.config),
    )
    env = EstimatorInfoWrapper(env, ekf)
    obs, info = env.reset(seed=0)
    info["estimate_lateral_offset"], info["estimate_weights"]
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv, VectorWrapper

from estimators.arx_state_space import PHYSICAL_STATE_NAMES
from estimators.base import Estimate, LaneEstimator, inputs_from_info, measurements_from_info
from estimators.evidence import DECISIONS
from estimators.road_geometry import lane_points_ahead, look_ahead_distances
from estimators.settings import FilterSettings
from estimators.timing import check_sample_time, config_sample_time
from estimators.trust import TrainingRecord, trusted_filter
from hasa_env.envs.base import hasa_unwrapped
from hasa_env.sim.road import Road
from hasa_env.steering.design import SteeringModelLike

__all__ = [
    "EstimatorInfoWrapper",
    "EstimatorObservationWrapper",
    "VectorEstimatorInfoWrapper",
    "VectorEstimatorObservationWrapper",
    "estimate_info_keys",
    "estimate_observation_names",
    "estimator_wrapper",
]


def estimate_info_keys(prefix: str = "estimate_") -> tuple[str, ...]:
    """Keys the wrappers add to ``info``.

    ``<prefix>lateral_offset`` (m), ``<prefix>lateral_offset_std`` (m),
    ``<prefix>lateral_velocity`` (m/s), ``<prefix>longitudinal_velocity`` (m/s),
    ``<prefix>bias`` (m), ``<prefix>lane_index`` (int, index of the most
    likely of the env's hypotheses), ``<prefix>weights`` (H,) (probability of
    each of the env's H hypotheses), ``<prefix>mean`` (n,) and ``<prefix>std``
    (n,) (mixture mean and standard deviations of the estimator's n states),
    ``<prefix>decision`` (str: ``"undecided"``, ``"decided"`` or
    ``"model_mismatch"``, :mod:`estimators.evidence`), ``<prefix>decision_code``
    (int, 0 / 1 / 2 in that order), ``<prefix>model_error`` (the statistic
    behind a mismatch; NaN before the steering channel has data) and
    ``<prefix>evidence_scale`` (what the last step's evidence was divided by).
    """
    names = (
        "lateral_offset",
        "lateral_offset_std",
        "lateral_velocity",
        "longitudinal_velocity",
        "bias",
        "lane_index",
        "weights",
        "mean",
        "std",
        "decision",
        "decision_code",
        "model_error",
        "evidence_scale",
    )
    return tuple(prefix + name for name in names)


def estimate_observation_names(num_hypotheses: int) -> tuple[str, ...]:
    """Entries of the estimate observation: mixture mean and std of
    [v_x, y, v_y, b], then the probability of each of the env's hypotheses."""
    return (
        *(f"mean_{name}" for name in PHYSICAL_STATE_NAMES),
        *(f"std_{name}" for name in PHYSICAL_STATE_NAMES),
        *(f"weight_{i}" for i in range(num_hypotheses)),
    )


def _estimate_values(est: Estimate, hypotheses: np.ndarray) -> tuple[np.ndarray, ...]:
    """(mean, std, weights per env hypothesis, lane index) with a leading run axis.

    The weights are mapped onto the env's hypotheses by bias value, so every
    estimator (also the one-component oracle and single-hypothesis filters)
    reports the probability of each of the env's lanes.
    """
    mean, std = np.atleast_2d(est.mean), np.atleast_2d(est.std)
    weights = np.atleast_2d(est.weights)
    own = np.atleast_2d(est.hypotheses)
    match = np.isclose(own[:, :, None], hypotheses[None, None, :], rtol=0.0, atol=1e-9)
    per_lane = np.einsum("rc,rch->rh", weights, match.astype(np.float64))
    return mean, std, per_lane, np.argmax(per_lane, axis=1)


def _info_values(est: Estimate, hypotheses: np.ndarray, prefix: str) -> dict[str, np.ndarray]:
    mean, std, weights, lane = _estimate_values(est, hypotheses)
    keys = estimate_info_keys(prefix)
    n_runs = mean.shape[0]
    decision = np.broadcast_to(np.asarray(est.decision, dtype=str), (n_runs,))
    values = (
        mean[:, 1],
        std[:, 1],
        mean[:, 2],
        mean[:, 0],
        mean[:, 3],
        lane.astype(np.int64),
        weights,
        mean,
        std,
        decision,
        np.select([decision == name for name in DECISIONS], range(len(DECISIONS)), -1),
        np.broadcast_to(np.asarray(est.model_error, dtype=np.float64), (n_runs,)),
        np.broadcast_to(np.asarray(est.evidence_scale, dtype=np.float64), (n_runs,)),
    )
    return dict(zip(keys, values, strict=True))


# bounds of the estimate observation (mean of v_x, y, v_y, b; their std), saturating
_MEAN_LOW = (-10.0, -60.0, -200.0, -60.0)
_MEAN_HIGH = (200.0, 60.0, 200.0, 60.0)
_STD_HIGH = 100.0


def _observation_bounds(num_hypotheses: int) -> tuple[np.ndarray, np.ndarray]:
    low = np.array([*_MEAN_LOW, *([0.0] * 4), *([0.0] * num_hypotheses)])
    high = np.array([*_MEAN_HIGH, *([_STD_HIGH] * 4), *([1.0] * num_hypotheses)])
    return low, high


def _observation(est: Estimate, hypotheses: np.ndarray) -> np.ndarray:
    mean, std, weights, _ = _estimate_values(est, hypotheses)
    low, high = _observation_bounds(hypotheses.shape[-1])
    obs = np.concatenate([mean[:, :4], std[:, :4], weights], axis=1)
    return np.clip(obs, low, high).astype(np.float32)


def _observation_space(num_hypotheses: int) -> spaces.Box:
    low, high = _observation_bounds(num_hypotheses)
    return spaces.Box(low.astype(np.float32), high.astype(np.float32), dtype=np.float32)


def _markings(config: Mapping[str, Any] | None) -> tuple[np.ndarray, np.ndarray | None]:
    if config is None:
        raise ValueError(
            "cannot find the env's config (markings.hypotheses); pass hypotheses= to the wrapper"
        )
    hyp = np.asarray(config["markings"]["hypotheses"], dtype=np.float64)
    prob = config["markings"].get("probabilities")
    return hyp, (None if prob is None else np.asarray(prob, dtype=np.float64))


def _check_timing(config: Mapping[str, Any] | None, estimator: LaneEstimator) -> None:
    if config is None:
        return
    step, frequency, repeat = config_sample_time(config)
    try:
        check_sample_time(
            estimator, step, source="the env", sim_frequency=frequency, action_repeat=repeat
        )
    except ValueError as exc:
        if repeat == 1:
            raise
        raise ValueError(
            f"{exc}. For a policy acting every {repeat} samples with an estimate made from "
            "every sample, use the advisor task gym.make('hasa_env/LaneKeepingAdvisor-v0', "
            f"config={{'action_repeat': {repeat}}}) (import advisor_tasks first), whose estimator "
            "steps at the simulation rate inside each env step"
        ) from None


def _env_road(env: Any) -> Road | None:
    """The env's road (single env, native vector env, or gymnasium's vector envs)."""
    setup = getattr(env.unwrapped, "setup", None)
    if setup is None:
        try:
            setup = env.get_attr("setup")[0]
        except (AttributeError, IndexError):
            return None
    return getattr(setup, "road", None)


class _RoadPoints:
    """The road points of the cars' stations (None on a straight road), for the estimator."""

    def __init__(self, env: Any, estimator: LaneEstimator) -> None:
        road = _env_road(env)
        self.road = None if road is None or road.is_straight else road
        self.near, self.far = look_ahead_distances(estimator)

    def kwargs(self, info: Mapping[str, Any], rows: np.ndarray | None = None) -> dict[str, Any]:
        if self.road is None:
            return {}
        station = np.asarray(info["station"], dtype=np.float64)
        if rows is not None:
            station = station[rows]
        return {"road_points": lane_points_ahead(self.road, station, self.near, self.far)}


def _single_config(env: gym.Env) -> Mapping[str, Any] | None:
    return getattr(env.unwrapped, "config", None)


def _vector_config(env: VectorEnv) -> Mapping[str, Any] | None:
    config = getattr(env.unwrapped, "config", None)
    if config is not None:
        return config
    get_attr = getattr(env, "get_attr", None)  # gymnasium's sync / async vector envs
    try:
        return None if get_attr is None else get_attr("config")[0]
    except (AttributeError, IndexError):
        return None


class EstimatorInfoWrapper(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Runs ``estimator`` on the env's sensors and puts its estimate in ``info``.

    At ``reset`` the estimator is reset with the first measurements and the
    env's lane hypotheses; each ``step`` feeds it that step's measurements
    and IMU. ``info`` gains :func:`estimate_info_keys` (same keys every
    time); :attr:`estimate` holds the last :class:`~estimators.base.Estimate`.
    Given a vector env this constructs a :class:`VectorEstimatorInfoWrapper`.

    Args:
        env: a hasa env whose step (``action_repeat / sim_frequency``) equals
            the estimator's dt and its steering model's Ts
            (:func:`estimators.timing.check_sample_time`). On a curved track
            the estimator gets the road ahead of ``info["station"]``
            (:func:`estimators.road_geometry.lane_points_ahead`).
        estimator: any :class:`~estimators.base.LaneEstimator`.
        hypotheses: lane hypotheses b_i (m); default the env's config.
        prior: their probabilities; default the env's config (uniform if unset).
        prefix: prefix of the info keys.
    """

    def __new__(cls, env: Any, *args: Any, **kwargs: Any) -> Any:
        if isinstance(env, VectorEnv):
            vector_cls = (
                VectorEstimatorObservationWrapper
                if issubclass(cls, EstimatorObservationWrapper)
                else VectorEstimatorInfoWrapper
            )
            return vector_cls(env, *args, **kwargs)
        return super().__new__(cls)

    def __init__(
        self,
        env: gym.Env,
        estimator: LaneEstimator,
        *,
        hypotheses: np.ndarray | None = None,
        prior: np.ndarray | None = None,
        prefix: str = "estimate_",
    ) -> None:
        gym.utils.RecordConstructorArgs.__init__(
            self, estimator=estimator, hypotheses=hypotheses, prior=prior, prefix=prefix
        )
        gym.Wrapper.__init__(self, env)
        config = _single_config(env)
        _check_timing(config, estimator)
        if hypotheses is None:
            hypotheses, config_prior = _markings(config)
            prior = config_prior if prior is None else prior
        self.estimator = estimator
        self.hypotheses = np.asarray(hypotheses, dtype=np.float64)
        self.prior = prior
        self.prefix = prefix
        self.estimate: Estimate | None = None
        self._road_points = _RoadPoints(env, estimator)

    def _add(self, info: dict[str, Any], est: Estimate) -> dict[str, Any]:
        info = dict(info)
        for key, value in _info_values(est, self.hypotheses, self.prefix).items():
            value = value[0]
            if value.ndim:
                info[key] = value.copy()
            elif value.dtype.kind == "i":
                info[key] = int(value)
            elif value.dtype.kind == "U":
                info[key] = str(value)
            else:
                info[key] = float(value)
        return info

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Any, dict[str, Any]]:
        obs, info = self.env.reset(seed=seed, options=options)
        self.estimate = self.estimator.reset(
            measurements_from_info(info),
            self.hypotheses,
            prior=self.prior,
            true_bias=float(info["bias"]),
            **self._road_points.kwargs(info),
        )
        return obs, self._add(info, self.estimate)

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        self.estimate = self.estimator.step(
            measurements_from_info(info), inputs_from_info(info), **self._road_points.kwargs(info)
        )
        return obs, reward, terminated, truncated, self._add(info, self.estimate)


class EstimatorObservationWrapper(EstimatorInfoWrapper):
    """Like :class:`EstimatorInfoWrapper`, and the observation becomes the estimate.

    Observation: ``Box`` float32 of length 8 + H,
    :func:`estimate_observation_names`: mixture mean and standard deviation
    of [v_x, y, v_y, b], then the probability of each of the env's H lane
    hypotheses (values saturate at the space's bounds: means of v_x in
    [-10, 200] m/s, y in [-60, 60] m, v_y in [-200, 200] m/s, b in [-60, 60] m;
    standard deviations in [0, 100]). Given a vector env
    this constructs a :class:`VectorEstimatorObservationWrapper`.
    """

    def __init__(self, env: gym.Env, estimator: LaneEstimator, **kwargs: Any) -> None:
        super().__init__(env, estimator, **kwargs)
        self.observation_space = _observation_space(self.hypotheses.shape[-1])

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        _, info = super().reset(seed=seed, options=options)
        assert self.estimate is not None  # (set by the reset)
        return _observation(self.estimate, self.hypotheses)[0], info

    def step(self, action: Any) -> tuple[np.ndarray, SupportsFloat, bool, bool, dict[str, Any]]:
        _, reward, terminated, truncated, info = super().step(action)
        assert self.estimate is not None  # (set by the step)
        return _observation(self.estimate, self.hypotheses)[0], reward, terminated, truncated, info


class VectorEstimatorInfoWrapper(VectorWrapper):
    """The vector-env form of :class:`EstimatorInfoWrapper`: one estimator batch for all cars.

    ``infos`` gains :func:`estimate_info_keys` as arrays with a leading car
    axis (and gymnasium's ``"_key"`` masks). A car the env autoresets
    (``NEXT_STEP``: on the step after its episode ended; ``SAME_STEP``: on the
    step it ended) gets its estimator slot re-initialised from its reset
    measurements; the other cars are stepped.
    """

    def __init__(
        self,
        env: VectorEnv,
        estimator: LaneEstimator,
        *,
        hypotheses: np.ndarray | None = None,
        prior: np.ndarray | None = None,
        prefix: str = "estimate_",
    ) -> None:
        super().__init__(env)
        config = _vector_config(env)
        _check_timing(config, estimator)
        mode = env.metadata.get("autoreset_mode", AutoresetMode.NEXT_STEP)
        if mode not in (AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP):
            raise ValueError(
                f"autoreset mode {mode} is not supported; use NEXT_STEP (default) or SAME_STEP"
            )
        self.autoreset_mode = mode
        if hypotheses is None:
            hypotheses, config_prior = _markings(config)
            prior = config_prior if prior is None else prior
        self.estimator = estimator
        self.hypotheses = np.asarray(hypotheses, dtype=np.float64)
        self.prior = prior
        self.prefix = prefix
        self.estimate: Estimate | None = None
        self._ended = np.zeros(self.num_envs, dtype=bool)
        self._road_points = _RoadPoints(env, estimator)

    def _add(self, infos: dict[str, Any], est: Estimate) -> dict[str, Any]:
        infos = dict(infos)
        mask = np.ones(self.num_envs, dtype=bool)
        for key, value in _info_values(est, self.hypotheses, self.prefix).items():
            infos[key] = np.array(value, copy=True)
            infos["_" + key] = mask
        return infos

    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Any, dict[str, Any]]:
        # gymnasium's VectorEnv.reset says seed: int, its vector envs take a list too
        obs, infos = self.env.reset(seed=seed, options=options)  # type: ignore[arg-type]
        mask = None if options is None else options.get("reset_mask")
        if mask is None or self.estimate is None:
            self.estimate = self.estimator.reset(
                measurements_from_info(infos),
                self.hypotheses,
                prior=self.prior,
                true_bias=np.asarray(infos["bias"], dtype=np.float64),
                **self._road_points.kwargs(infos),
            )
            self._ended[:] = False
        else:  # gymnasium's partial reset: restart only those cars' filters
            idx = np.flatnonzero(np.asarray(mask, dtype=bool))
            self.estimate = self.estimator.reset(
                measurements_from_info(infos)[idx],
                self.hypotheses,
                prior=self.prior,
                true_bias=np.asarray(infos["bias"], dtype=np.float64)[idx],
                runs=idx,
                **self._road_points.kwargs(infos, idx),
            )
            self._ended[idx] = False
        return obs, self._add(infos, self.estimate)

    def step(self, actions: Any) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        obs, rewards, terminated, truncated, infos = self.env.step(actions)
        measurement = measurements_from_info(infos)
        acceleration = inputs_from_info(infos)
        done = np.asarray(terminated) | np.asarray(truncated)
        if self.autoreset_mode == AutoresetMode.NEXT_STEP:
            restarted = self._ended.copy()
            self._ended = done
        else:  # SAME_STEP: the env already reset the cars that ended, info is their new start
            restarted = done
        stepping = ~restarted
        road = self._road_points
        if stepping.all():
            est = self.estimator.step(measurement, acceleration, **road.kwargs(infos))
        else:
            if stepping.any():
                est = self.estimator.step(
                    measurement[stepping],
                    acceleration[stepping],
                    runs=np.flatnonzero(stepping),
                    **road.kwargs(infos, stepping),
                )
            est = self.estimator.reset(
                measurement[restarted],
                self.hypotheses,
                prior=self.prior,
                true_bias=np.asarray(infos["bias"], dtype=np.float64)[restarted],
                runs=np.flatnonzero(restarted),
                **road.kwargs(infos, restarted),
            )
        self.estimate = est
        return obs, rewards, terminated, truncated, self._add(infos, est)


class VectorEstimatorObservationWrapper(VectorEstimatorInfoWrapper):
    """The vector-env form of :class:`EstimatorObservationWrapper`: observations
    (N, 8 + H) float32 (:func:`estimate_observation_names`)."""

    def __init__(self, env: VectorEnv, estimator: LaneEstimator, **kwargs: Any) -> None:
        super().__init__(env, estimator, **kwargs)
        self.single_observation_space = _observation_space(self.hypotheses.shape[-1])
        self.observation_space = gym.vector.utils.batch_space(
            self.single_observation_space, self.num_envs
        )

    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        _, infos = super().reset(seed=seed, options=options)
        assert self.estimate is not None  # (set by the reset)
        return _observation(self.estimate, self.hypotheses), infos

    def step(
        self, actions: Any
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        _, rewards, terminated, truncated, infos = super().step(actions)
        assert self.estimate is not None  # (set by the step)
        return _observation(self.estimate, self.hypotheses), rewards, terminated, truncated, infos


def estimator_wrapper(
    model: SteeringModelLike,
    steering_ratio: float = 1.0,
    *,
    training: TrainingRecord | None = None,
    overrides: Mapping[str, Any] | None = None,
) -> Callable[[gym.Env], EstimatorInfoWrapper]:
    """A wrapper factory: the Gaussian-mixture EKF runs alongside each env it wraps.

    Used as ``hasa_env.session.DriveSession(env_wrapper=...)`` by ``hasa-drive
    --estimator``: each run's env is wrapped in :class:`EstimatorInfoWrapper`
    with the filter :func:`estimators.trust.trusted_filter` makes of the steering
    ``model`` on filter settings from the env's config, so
    ``info["estimate_weights"]`` carries the live hypothesis weights the HUD
    shows (the recording keeps its standard columns). ``steering_ratio``:
    model units per road-wheel radian (15 for the paper's presets,
    :func:`hasa_env.steering.loading.default_steering_ratio`); ``training``
    and ``overrides``: as :func:`~estimators.trust.trusted_filter` takes them (the
    model's own record of its training roads and speeds limits where its steering counts).
    """
    arx = model.arx()
    if arx is None:
        raise ValueError(
            f"the steering model {model.name!r} has no ARX form (arx() is None): the estimator "
            "needs one"
        )

    def wrap(env: gym.Env) -> EstimatorInfoWrapper:
        config = hasa_unwrapped(env).config
        dt = config["action_repeat"] / config["sim_frequency"]
        trusted = trusted_filter(
            model,
            FilterSettings.from_env_config(config),
            steering_ratio=steering_ratio,
            training=training,
            overrides=overrides,
        )
        return EstimatorInfoWrapper(env, trusted.estimator(dt=dt))

    return wrap
