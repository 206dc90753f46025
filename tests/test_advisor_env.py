"""The human-as-advisor task (advisor_tasks.env / advisor_tasks.vector): spaces, config,
determinism, the estimator at the simulation rate, and the vector twin bit for bit."""

from __future__ import annotations

import sys
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import advisor_tasks
from advisor_tasks.setup import ADVISOR_INFO_KEYS, default_config, observation_names
from hasa_env import ConfigError

ID = "hasa_env/LaneKeepingAdvisor-v0"
CURVED = "hasa_env/LaneKeepingAdvisorCurved-v0"
SHORT = {
    "time_limit": 0.5,
    "initial_state": {"lateral_offset_std": 1.0, "heading_std": 0.08},
}
"""Short episodes that often leave the road: truncations and terminations at many times."""


def _vec(env_id: str, n: int, config: dict) -> gym.vector.VectorEnv:
    return gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point", config=config)


def _same_step(vector_out, single_out, i: int) -> None:
    obs, reward, terminated, truncated, info = vector_out
    o, r, te, tr, inf = single_out
    assert np.array_equal(obs[i], o)
    assert (reward[i], terminated[i], truncated[i]) == (r, te, tr)
    assert set(inf) == set(ADVISOR_INFO_KEYS)
    for key, value in inf.items():  # NaN (e.g. no model-error statistic yet) equals NaN
        np.testing.assert_array_equal(np.asarray(info[key][i]), np.asarray(value), err_msg=key)


@pytest.mark.slow
def test_registered_by_advisor_tasks_with_entry_point_strings():
    for env_id in advisor_tasks.ADVISOR_ENV_IDS:
        spec = gym.spec(env_id)
        assert spec.entry_point == "advisor_tasks.env:LaneKeepingAdvisorEnv"
        assert spec.vector_entry_point == "advisor_tasks.vector:LaneKeepingAdvisorVectorEnv"
    import subprocess

    # hasa_env registers only its own ids and imports nothing above it; advisor_tasks
    # registers the task without importing the estimators until an env is made
    code = (
        "import sys, gymnasium as gym, hasa_env\n"
        "print('hasa_env/LaneKeepingAdvisor-v0' in gym.registry, 'estimators' in sys.modules)\n"
        "import advisor_tasks\n"
        "print('hasa_env/LaneKeepingAdvisor-v0' in gym.registry, 'estimators' in sys.modules)\n"
        "gym.make('hasa_env/LaneKeepingAdvisor-v0')\n"
        "print('estimators' in sys.modules)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split("\n")[:3] == ["False False", "True False", "True"]


@pytest.mark.slow
def test_make_with_module_prefix_imports_the_task():
    import subprocess

    code = (
        "import gymnasium as gym\n"
        "env = gym.make('advisor_tasks:hasa_env/LaneKeepingAdvisor-v0')\n"
        "print(type(env.unwrapped).__name__)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "LaneKeepingAdvisorEnv"


@pytest.mark.parametrize("env_id", [ID, CURVED])
def test_gymnasium_and_sb3_check_env_are_clean(env_id):
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(gym.make(env_id, config={"time_limit": 1.0}).unwrapped, skip_render_check=True)
        sb3_check_env(gym.make(env_id, config={"time_limit": 1.0}), warn=True)


def test_spaces_and_the_same_info_keys_at_reset_and_step():
    env = gym.make(ID, config={"action_repeat": 4})
    assert env.action_space.shape == (1,)
    names = observation_names(2)
    assert env.observation_space.shape == (len(names),) == (17,)
    obs, info = env.reset(seed=1)
    assert list(info) == list(ADVISOR_INFO_KEYS)
    assert obs.dtype == np.float32 and env.observation_space.contains(obs)
    obs, _, _, _, step_info = env.step(env.action_space.sample())
    assert list(step_info) == list(info)
    assert step_info["substep_lateral_offset"].shape == (4,)
    assert step_info["substep_lateral_offset"][-1] == step_info["lateral_offset"]
    # the observation holds the estimate, the lane weights, the raw sensors and the wheel
    assert obs[names.index("estimate_lateral_offset")] == np.float32(
        step_info["estimate_lateral_offset"]
    )
    weights = [obs[names.index(f"estimate_weight_{i}")] for i in range(2)]
    assert np.allclose(weights, step_info["estimate_weights"], atol=1e-7)
    assert obs[names.index("sensor_camera_lateral")] == np.float32(
        step_info["sensor_camera_lateral"]
    )
    assert obs[-1] == np.float32(step_info["sensor_advisor_steering"])
    # the decision state, one-hot, and its statistic
    decision = [
        obs[names.index(f"estimate_{d}")] for d in ("undecided", "decided", "model_mismatch")
    ]
    assert sorted(decision) == [0.0, 0.0, 1.0]
    assert decision.index(1.0) == step_info["estimate_decision_code"]
    assert step_info["estimate_decision"] in ("undecided", "decided", "model_mismatch")
    full = gym.make(ID, config={"action": {"steering_only": False, "type": "physical"}})
    assert full.action_space.shape == (2,)


def test_deterministic_per_seed_and_random_advisors_per_episode():
    def run(seed: int) -> tuple[np.ndarray, list[int]]:
        env = gym.make(ID, config=SHORT)
        rng = np.random.default_rng(0)
        obs, info = env.reset(seed=seed)
        out, advisors = [obs], [info["advisor_index"]]
        for _ in range(150):
            obs, _, terminated, truncated, info = env.step(rng.uniform(-1, 1, 1).astype(np.float32))
            out.append(obs)
            if terminated or truncated:
                obs, info = env.reset()
                advisors.append(info["advisor_index"])
        return np.array(out), advisors

    a, advisors = run(3)
    b, again = run(3)
    assert np.array_equal(a, b) and advisors == again
    assert len(set(advisors)) > 1  # "random": a new human is drawn per episode
    assert not np.array_equal(a, run(4)[0])


def test_config_is_deep_merged_and_errors_name_the_key_and_the_range():
    env = gym.make(ID, config={"advisor": {"driver": "Ill"}, "noise": {"camera": 0.1}})
    config = env.unwrapped.config
    assert config["advisor"]["driver"] == "Ill" and config["advisor"]["population"] == "paper"
    assert config["noise"]["camera"] == 0.1 and config["noise"]["speed"] == 0.05
    assert config["disturbance"]["crosswind"] == 0.1  # the population's study conditions
    assert set(default_config()) == set(config)
    for bad, message in [
        ({"advisor": {"population": "x"}}, r"'advisor\.population' = 'x' is not allowed: one of"),
        ({"advisor": {"driver": "nobody"}}, r"'advisor\.driver' = 'nobody'.*'Ill'"),
        ({"advisor": {"drver": 1}}, r"unknown config key 'advisor\.drver'"),
        ({"estimator": {"steering_ratio": 0}}, r"'estimator\.steering_ratio' = 0 .*\(0, 100\]"),
        ({"estimator": {"settings": {"bias_std": -1}}}, r"'estimator\.settings'.*bias_std"),
        ({"observation": {"type": "state"}}, r"'observation' does not apply"),
        ({"noise": {"camera": -1}}, r"'noise\.camera' = -1 is out of range: allowed \[0, 10\] m"),
        ({"estimator": {"steering_model": "no-such-model"}}, r"'estimator\.steering_model'"),
    ]:
        with pytest.raises(ConfigError, match=message):
            gym.make(ID, config=bad)


@pytest.mark.parametrize(
    "env_id, config",
    [
        (ID, SHORT),
        (ID, {**SHORT, "action_repeat": 3}),
        (ID, {**SHORT, "action_repeat": 2, "advisor": {"drives": "human"}}),
        (CURVED, {**SHORT, "action_repeat": 2, "action": {"steering_only": False}}),
        (ID, {**SHORT, "scenario": "off_centre_drivers", "advisor": {"drives": "human"}}),
    ],
    ids=["car drives", "action_repeat 3", "human drives", "curved, acceleration", "scenario"],
)
def test_car_i_of_the_vector_env_is_the_single_env_seeded_seed_plus_i(env_id, config):
    n, seed = 3, 11
    vector = _vec(env_id, n, config)
    singles = [gym.make(env_id, config=config) for _ in range(n)]
    obs, info = vector.reset(seed=seed)
    for i, single in enumerate(singles):
        o, inf = single.reset(seed=seed + i)
        _same_step(
            (obs, np.zeros(n), np.zeros(n, bool), np.zeros(n, bool), info),
            (o, 0.0, False, False, inf),
            i,
        )
    rng = np.random.default_rng(5)
    pending, ends = [False] * n, 0
    for _ in range(120):
        actions = (0.5 * rng.uniform(-1, 1, vector.action_space.shape)).astype(np.float32)
        out = vector.step(actions)
        for i, single in enumerate(singles):
            if pending[i]:  # NEXT_STEP autoreset: the car restarts, its action is ignored
                o, inf = single.reset()
                expected = (o, 0.0, False, False, inf)
                pending[i] = False
            else:
                expected = single.step(actions[i])
                pending[i] = expected[2] or expected[3]
                ends += pending[i]
            _same_step(out, expected, i)
    assert ends >= 2 * n, "too few episode ends: the autoresets are hardly tested"


def test_partial_reset_restarts_only_the_masked_cars():
    n = 3
    vector, untouched = _vec(ID, n, SHORT), _vec(ID, n, SHORT)
    vector.reset(seed=0)
    untouched.reset(seed=0)
    actions = np.zeros((n, 1), np.float32)
    for _ in range(5):
        vector.step(actions)
        untouched.step(actions)
    mask = np.array([False, True, False])
    before = vector.step(actions)[4]
    untouched.step(actions)
    obs, info = vector.reset(seed=[None, 42, None], options={"reset_mask": mask})
    assert np.array_equal(info["_time"], mask) and info["time"][1] == 0.0
    single = gym.make(ID, config=SHORT)
    o, inf = single.reset(seed=42)
    assert np.array_equal(obs[1], o) and inf["advisor_index"] == info["advisor_index"][1]
    after = vector.step(actions)
    expected = single.step(actions[1])
    _same_step(after, expected, 1)
    assert after[4]["time"][0] == pytest.approx(before["time"][0] + 0.01)  # the others went on
    reference = untouched.step(actions)
    for i in (0, 2):  # exactly as if car 1 had not been reset
        obs_r, reward_r, terminated_r, truncated_r, info_r = reference
        row = {key: value[i] for key, value in info_r.items() if not key.startswith("_")}
        _same_step(after, (obs_r[i], reward_r[i], terminated_r[i], truncated_r[i], row), i)


def test_an_env_step_of_action_repeat_r_is_r_samples_of_the_estimator():
    """action_repeat 10 (a 10 Hz policy): the estimate is the one of the 100 Hz env whose
    policy holds each action for 10 steps, bit for bit."""
    slow = gym.make(ID, config={"action_repeat": 10})
    fast = gym.make(ID, config={"action_repeat": 1})
    obs_slow, _ = slow.reset(seed=2)
    obs_fast, _ = fast.reset(seed=2)
    assert np.array_equal(obs_slow, obs_fast)
    rng = np.random.default_rng(0)
    for _ in range(30):
        action = (0.05 * rng.uniform(-1, 1, 1)).astype(np.float32)
        obs_slow, *_, info_slow = slow.step(action)
        for _ in range(10):
            obs_fast, *_, info_fast = fast.step(action)
        assert np.array_equal(obs_slow, obs_fast)
        for key in ("estimate_lateral_offset", "estimate_weights", "sensor_advisor_steering"):
            assert np.array_equal(info_slow[key], info_fast[key])


@pytest.mark.parametrize("bias_index", [0, 1])
def test_with_the_car_driving_the_human_advice_finds_the_true_lane(bias_index):
    env = gym.make(ID, config={"action_repeat": 10, "advisor": {"driver": "Ill"}})
    obs, info = env.reset(seed=0, options={"bias_index": bias_index})
    for _ in range(50):  # 5 s of a lane keeper on the true state at 10 Hz
        steer = -0.15 * info["lateral_offset"] - 0.8 * info["heading"]
        obs, _, terminated, _, info = env.step(np.array([steer / 0.5], np.float32))
        assert not terminated
    assert info["estimate_weights"][bias_index] > 0.99
    assert abs(info["estimate_lateral_offset"] - info["lateral_offset"]) < 0.15
    assert info["policy_steering"] == pytest.approx(info["steering"])
    assert info["advisor_steering"] != info["steering"]  # the human only advises


def test_the_human_drives_and_the_action_is_ignored():
    env = gym.make(ID, config={"advisor": {"drives": "human", "driver": 0}})
    env.reset(seed=0)
    for _ in range(100):
        *_, info = env.step(np.array([1.0], np.float32))  # full lock, ignored
    assert info["steering"] == info["advisor_steering"] and info["policy_steering"] == 0.5
    assert info["sensor_advisor_steering"] == info["sensor_steering"]
    assert abs(info["lateral_offset"]) < 1.0


@pytest.mark.slow
def test_the_advisors_keep_the_scenarios_preferred_offsets():
    from hasa_env.drivers import population
    from hasa_env.scenarios import scenario_drivers

    config = {"scenario": "off_centre_drivers", "advisor": {"population_seed": 2}}
    drivers = gym.make(ID, config=config).unwrapped.setup.drivers
    assert list(drivers) == scenario_drivers(population("paper", 2, 9), "off_centre_drivers", 2)
    assert all(0.2 <= abs(d.preferred_offset) <= 0.5 for d in drivers)
    assert all(d.preferred_offset == 0.0 for d in gym.make(ID).unwrapped.setup.drivers)

    def mean_offset(scenario_config: dict) -> float:
        """The car's mean lateral offset (m) over seconds 20-25 with the human driving."""
        advisor = {**scenario_config["advisor"], "drives": "human", "driver": "Ill"}
        env = gym.make(ID, config={**scenario_config, "action_repeat": 10, "advisor": advisor})
        env.reset(seed=0)
        offsets = []
        for k in range(250):
            *_, terminated, _, info = env.step(np.zeros(1, np.float32))
            assert not terminated
            offsets.extend(info["substep_lateral_offset"] if k >= 200 else [])
        return float(np.mean(offsets))

    # the same markings and seeds without the scenario's drivers: only the offset differs
    # (the human drifts to it with a time constant of about 5 s)
    preferred = next(d.preferred_offset for d in drivers if d.name == "Ill")
    keeping = mean_offset(config)
    centred = mean_offset(
        {"markings": {"hypotheses": [0.0, -0.8]}, "advisor": {"population_seed": 2}}
    )
    assert keeping - centred == pytest.approx(preferred, abs=0.03)


def test_fitted_models_train_on_the_scenarios_first_driver(monkeypatch):
    """'fit:' models are fitted on a run of the population's first driver as it drives in
    the scenario (keeping its preferred offset, like the advisors and hasa-bench's)."""
    from advisor_tasks import config as advisor_config
    from hasa_env.drivers import population
    from hasa_env.scenarios import scenario_drivers

    trainers = []

    def capture(params):
        trainers.append(params)
        raise RuntimeError("stop before the training run")

    monkeypatch.setattr(advisor_config, "make_driver", capture)
    advisor_config._fitted_model.cache_clear()
    config = {
        "scenario": "off_centre_drivers",
        "advisor": {"population_seed": 5},
        "estimator": {"steering_model": "fit:generalized"},
    }
    try:
        with pytest.raises(RuntimeError, match="stop before"):
            gym.make(ID, config=config)
    finally:
        advisor_config._fitted_model.cache_clear()
    expected = scenario_drivers(population("paper", 5, 9), "off_centre_drivers", 5)[0]
    assert trainers == [expected] and expected.preferred_offset != 0.0


def test_invalid_actions_and_reset_options_are_refused():
    env = gym.make(ID).unwrapped
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"finite, got \[steering=nan\]$"):  # its one element
        env.step(np.array([np.nan], np.float32))
    with pytest.raises(ValueError, match="shape"):
        env.step(np.zeros(2, np.float32))
    with pytest.raises(ValueError, match="advisor_index"):
        env.reset(options={"advisor_index": 9})
    _, info = env.reset(seed=0, options={"advisor_index": 4, "bias_index": 1})
    assert info["advisor_index"] == 4 and info["bias_index"] == 1
    with pytest.raises(ValueError, match="unknown reset option"):
        _vec(ID, 2, {}).reset(options={"nope": 1})
    with pytest.raises(ValueError, match=r"allowed keys here: advisor_index, bias, .*; did you "
                       r"mean 'advisor_index'\?"):  # fmt: skip
        env.reset(options={"advisr_index": 1})


def test_the_estimator_wrappers_point_to_the_advisor_task_for_a_slow_policy():
    from estimators import EstimatorInfoWrapper, GaussianMixtureEKF
    from hasa_env.steering.models import GeneralizedModel

    env = gym.make("hasa_env/LaneKeeping-v0", config={"action_repeat": 10})
    with pytest.raises(ValueError, match=r"LaneKeepingAdvisor-v0.*'action_repeat': 10"):
        EstimatorInfoWrapper(env, GaussianMixtureEKF(GeneralizedModel.paper().arx()))


def test_sb3_adapter_over_the_vector_task_is_dummy_vec_env_over_single_envs():
    from stable_baselines3.common.vec_env import DummyVecEnv

    from hasa_env.rl import SB3VecEnv

    n = 2
    adapted = SB3VecEnv(_vec(ID, n, SHORT))
    reference = DummyVecEnv([lambda: gym.make(ID, config=SHORT) for _ in range(n)])
    adapted.seed(3)
    reference.seed(3)
    assert np.array_equal(adapted.reset(), reference.reset())
    rng = np.random.default_rng(0)
    dones = 0
    for _ in range(80):
        actions = (0.5 * rng.uniform(-1, 1, (n, 1))).astype(np.float32)
        obs_a, rewards_a, done_a, infos_a = adapted.step(actions)
        obs_b, rewards_b, done_b, infos_b = reference.step(actions)
        assert np.array_equal(obs_a, obs_b) and np.array_equal(rewards_a, rewards_b)
        assert np.array_equal(done_a, done_b)
        for i in np.flatnonzero(done_a):
            assert np.array_equal(
                infos_a[i]["terminal_observation"], infos_b[i]["terminal_observation"]
            )
        dones += int(done_a.sum())
    assert dones >= 2


def test_renders_headless_with_the_estimator_weights_in_the_info():
    env = gym.make(ID, render_mode="rgb_array")
    env.reset(seed=0)
    env.step(np.zeros(1, np.float32))
    frame = env.render()
    assert frame.shape == (480, 640, 3) and frame.dtype == np.uint8
    vector = gym.make_vec(
        ID, num_envs=2, vectorization_mode="vector_entry_point", render_mode="rgb_array"
    )
    vector.reset(seed=0)
    assert [f.shape for f in vector.render()] == [(480, 640, 3)] * 2


def test_a_straight_road_model_gives_no_lane_evidence_on_bends_unless_configured():
    from estimators.settings import STRAIGHT_CURVATURE

    env = gym.make("hasa_env/LaneKeepingAdvisorCurved-v0")
    assert env.unwrapped.estimator.settings.steering_curvature_limit == STRAIGHT_CURVATURE
    env.close()
    config = {"estimator": {"settings": {"steering_curvature_limit": 0.01}}}
    env = gym.make("hasa_env/LaneKeepingAdvisorCurved-v0", config=config)
    assert env.unwrapped.estimator.settings.steering_curvature_limit == 0.01
    env.close()
