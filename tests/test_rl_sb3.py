"""Stable-Baselines3: check_env on every id and wrapper, the vec-env adapter, a tiny PPO run."""

import dataclasses
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

pytest.importorskip("torch")
pytest.importorskip("stable_baselines3")

from stable_baselines3.common.env_checker import check_env  # noqa: E402
from stable_baselines3.common.vec_env import DummyVecEnv, VecMonitor  # noqa: E402

import hasa_env  # noqa: E402
from hasa_env.drivers import SpeedProfile, SyntheticDriver, population  # noqa: E402
from hasa_env.rl import (  # noqa: E402
    ActionRepeat,
    HumanAdvisor,
    SB3VecEnv,
    SteeringOnly,
    VectorSteeringOnly,
    make_vector_env,
)

ENV_ID = "hasa_env/LaneKeeping-v0"


def _check(env: gym.Env) -> list[str]:
    """Run SB3's check_env (it raises on failure); return its warnings."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env)
    return [str(w.message) for w in caught]


@pytest.mark.parametrize("env_id", hasa_env.ENV_IDS)
@pytest.mark.parametrize("observation", ["sensors", "state", "both"])
@pytest.mark.parametrize("action", ["normalized", "physical"])
def test_check_env_every_id_and_type(env_id, observation, action):
    config = {"observation": {"type": observation}, "action": {"type": action}}
    messages = _check(gym.make(env_id, config=config))
    if action == "normalized":
        assert messages == []
    else:  # SB3's only remark: it prefers a [-1, 1] action space
        assert messages and all("normalized Box action space" in m for m in messages)


def _ekf(config):
    from estimators.gm_ekf import GaussianMixtureEKF
    from estimators.settings import FilterSettings
    from hasa_env.steering.models import GeneralizedModel

    return GaussianMixtureEKF(
        GeneralizedModel.paper().arx(), FilterSettings.from_env_config(config)
    )


@pytest.mark.parametrize("env_id", hasa_env.ENV_IDS)
def test_check_env_estimator_observation_wrapper(env_id):
    wrappers = pytest.importorskip("estimators.wrappers")
    env = gym.make(env_id)
    wrapped = wrappers.EstimatorObservationWrapper(env, _ekf(env.unwrapped.config))
    assert _check(wrapped) == []
    info_only = wrappers.EstimatorInfoWrapper(gym.make(env_id), _ekf(env.unwrapped.config))
    assert _check(info_only) == []


def test_check_env_rl_wrappers():
    """The single-env wrapper stacks (steering only, action repeat, a human advisor under the
    estimator wrapper) that examples/train_ppo.py used before the advisor task."""
    wrappers = pytest.importorskip("estimators.wrappers")
    params = dataclasses.replace(population("paper", 0)[0], speed=SpeedProfile.hold())
    env = SteeringOnly(gym.make(ENV_ID))
    assert _check(ActionRepeat(env, 10)) == []
    advised = HumanAdvisor(SteeringOnly(gym.make(ENV_ID)), SyntheticDriver(params))
    stack = wrappers.EstimatorObservationWrapper(advised, _ekf(advised.unwrapped.config))
    assert _check(ActionRepeat(stack, 10)) == []


# ------------------------------------------------------------------ adapter
CONFIG = {
    "action_repeat": 10,
    "time_limit": 3.0,  # truncations every 30 steps
    "observation": {"type": "both"},  # a Dict observation
    "initial_state": {"lateral_offset_std": 1.0, "heading_std": 0.2},  # terminations too
}


VECTOR_ENVS = {
    "native": lambda n: gym.make_vec(
        ENV_ID, num_envs=n, vectorization_mode="vector_entry_point", config=CONFIG
    ),
    "partial-reset": lambda n: make_vector_env(ENV_ID, n, CONFIG),
    "sync next-step": lambda n: gym.make_vec(
        ENV_ID, num_envs=n, vectorization_mode="sync", config=CONFIG
    ),
    "sync same-step": lambda n: gym.make_vec(
        ENV_ID,
        num_envs=n,
        vectorization_mode="sync",
        vector_kwargs={"autoreset_mode": AutoresetMode.SAME_STEP},
        config=CONFIG,
    ),
}


@pytest.mark.parametrize("kind", sorted(VECTOR_ENVS))
def test_adapter_matches_dummy_vec_env(kind):
    """Same seeds, same actions: SB3VecEnv over a vector env == DummyVecEnv over single envs."""
    n = 4
    adapted = SB3VecEnv(VECTOR_ENVS[kind](n))
    reference = DummyVecEnv([lambda: gym.make(ENV_ID, config=CONFIG) for _ in range(n)])
    assert adapted.observation_space == reference.observation_space
    assert adapted.action_space == reference.action_space
    adapted.seed(7)
    reference.seed(7)
    obs_a, obs_b = adapted.reset(), reference.reset()
    rng = np.random.default_rng(1)
    terminations = truncations = 0
    for step in range(150):
        for key in ("sensors", "state"):
            np.testing.assert_array_equal(obs_a[key], obs_b[key], err_msg=f"{key} step {step}")
        # cars 0, 1 steer wildly (they leave the road), cars 2, 3 gently (time limit)
        scale = np.array([[1.0], [1.0], [0.03], [0.03]])
        actions = (scale * rng.uniform(-1, 1, (n, 2))).astype(np.float32)
        obs_a, rew_a, done_a, infos_a = adapted.step(actions)
        obs_b, rew_b, done_b, infos_b = reference.step(actions)
        np.testing.assert_array_equal(rew_a, rew_b)
        assert rew_a.dtype == rew_b.dtype
        np.testing.assert_array_equal(done_a, done_b)
        for i in range(n):
            a, b = infos_a[i], infos_b[i]
            assert a["TimeLimit.truncated"] == b["TimeLimit.truncated"]
            assert a["lateral_offset"] == b["lateral_offset"]  # the step's info, not the reset's
            assert ("terminal_observation" in a) == bool(done_b[i])
            if done_b[i]:
                for key in ("sensors", "state"):
                    np.testing.assert_array_equal(
                        a["terminal_observation"][key], b["terminal_observation"][key]
                    )
                assert (
                    adapted.reset_infos[i]["lateral_offset"]
                    == reference.reset_infos[i]["lateral_offset"]
                )
                truncations += int(b["TimeLimit.truncated"])
                terminations += int(not b["TimeLimit.truncated"])
    assert terminations >= 5 and truncations >= 5  # both kinds of episode end were crossed


def test_adapter_seed_options_and_errors():
    env = SB3VecEnv(make_vector_env(ENV_ID, 3))
    assert env.num_envs == 3 and env.render_mode is None
    env.set_options({"bias_index": 1})
    env.reset()
    assert [info["bias_index"] for info in env.reset_infos] == [1, 1, 1]
    env.set_options([{"bias_index": 0}, {"bias_index": 1}, {}])
    with pytest.raises(ValueError, match="one options dict"):
        env.reset()
    assert env.get_attr("num_envs") == [3, 3, 3]
    assert env.env_is_wrapped(gym.Wrapper) == [False, False, False]
    with pytest.raises(NotImplementedError, match="per-env objects"):
        env.env_method("render")
    # the native env made by gym.make_vec resets single cars itself (reset_mask)
    plain = gym.make_vec(ENV_ID, num_envs=2, vectorization_mode="vector_entry_point")
    adapted = SB3VecEnv(VectorSteeringOnly(plain))
    assert adapted.reset().shape == (2, 6)
    with pytest.raises(TypeError, match="VectorEnv"):
        SB3VecEnv(gym.make(ENV_ID))


def test_adapter_env_method_on_sync_vector_env():
    sync = gym.make_vec(ENV_ID, num_envs=2, vectorization_mode="sync")
    env = SB3VecEnv(sync)
    env.reset()
    assert env.get_attr("render_mode") == [None, None]
    assert env.env_method("get_wrapper_attr", "render_mode", indices=[1]) == [None]


@pytest.mark.slow
def test_tiny_ppo_run_on_the_native_vector_env():
    from stable_baselines3 import PPO

    config = {"action_repeat": 10, "time_limit": 3.0}
    venv = VecMonitor(SB3VecEnv(make_vector_env(ENV_ID, 4, config, steering_only=True)))
    venv.seed(0)
    model = PPO("MlpPolicy", venv, n_steps=128, batch_size=256, n_epochs=2, seed=0, device="cpu")
    model.learn(total_timesteps=2048)
    assert model.num_timesteps == 2048
    episodes = list(model.ep_info_buffer)
    assert len(episodes) >= 40  # 30-step episodes ended and were counted by VecMonitor
    assert all(1 <= ep["l"] <= 30 and np.isfinite(ep["r"]) for ep in episodes)
    assert any(ep["l"] == 30 for ep in episodes)  # some reached the 3 s time limit
    obs = venv.reset()
    actions, _ = model.predict(obs, deterministic=True)
    assert actions.shape == (4, 1) and np.all(np.abs(actions) <= 1.0)
    venv.close()


def test_adapter_refuses_stateful_vector_wrappers():
    """A partial reset under the vector estimator wrapper would re-initialise every car's filter."""
    wrappers = pytest.importorskip("estimators.wrappers")
    venv = make_vector_env(ENV_ID, 2)
    stateful = wrappers.EstimatorObservationWrapper(venv, _ekf(venv.unwrapped.config))
    with pytest.raises(TypeError, match="VectorEstimatorObservationWrapper"):
        SB3VecEnv(stateful)
    assert SB3VecEnv(VectorSteeringOnly(make_vector_env(ENV_ID, 2))).num_envs == 2  # stateless
