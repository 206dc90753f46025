"""The lane-keeping check: a steering model drives, and must keep the car on the road."""

from __future__ import annotations

import math
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import advisor_tasks  # noqa: F401  (registers the advisor ids and hasa_env's)
from hasa_cli import EXIT_USAGE
from hasa_cli.inputs import estimator_for
from hasa_cli.replay import main as replay_main
from hasa_env.drivers import (
    LaneKeepingCheck,
    SpeedProfile,
    lane_keeping_check,
    lane_keeping_checks,
    require_lane_keeping,
)
from hasa_env.envs.lane_keeping import LaneKeepingEnv
from hasa_env.sim.config import ConfigError
from hasa_env.steering.loading import PAPER_STEERING_RATIO, load_model

ADVISOR = "hasa_env/LaneKeepingAdvisor-v0"


def _flipped(model):
    """The model with its lane terms (bearings b, c and v_y d) negated: steers away."""
    blocks = {k: np.asarray(v, dtype=np.float64) for k, v in model.coefficients().items()}
    return model.with_parameters(np.concatenate([blocks["a"], *(-blocks[k] for k in "bcd")]))


def test_the_papers_generalized_model_keeps_the_car_on_the_road() -> None:
    check = lane_keeping_check(load_model("generalized"), steering_ratio=PAPER_STEERING_RATIO)
    assert check.passed and check.runs == 4 and check.runs_left_road == 0
    assert check.duration == 30.0 and math.isinf(check.first_exit)
    assert check.max_abs_lateral_offset < 1.0
    assert check.to_dict()["first_exit"] is None
    assert check.describe().startswith("keeps the car on the road")


def test_a_model_that_steers_away_from_the_lane_centre_drives_off_the_road() -> None:
    check = lane_keeping_check(
        _flipped(load_model("generalized")), steering_ratio=PAPER_STEERING_RATIO, runs=2
    )
    assert not check.passed and check.runs_left_road == 2
    assert check.first_exit < 10.0
    assert "drives off the road in 2 of 2 runs" in check.describe()
    assert isinstance(check, LaneKeepingCheck)


def test_several_models_at_once_get_their_own_outcomes() -> None:
    good, bad = load_model("generalized"), _flipped(load_model("generalized"))
    together = lane_keeping_checks([good, bad], steering_ratio=PAPER_STEERING_RATIO, runs=2)
    alone = [
        lane_keeping_check(m, steering_ratio=PAPER_STEERING_RATIO, runs=2) for m in (good, bad)
    ]
    assert together == alone and [c.passed for c in together] == [True, False]
    assert lane_keeping_checks([]) == []


def test_the_check_is_deterministic_and_uses_the_config() -> None:
    model = load_model("generalized")
    short = {"time_limit": 5.0, "disturbance": {"crosswind": 0.1}}
    a = lane_keeping_check(model, steering_ratio=PAPER_STEERING_RATIO, config=short, seed=3)
    b = lane_keeping_check(model, steering_ratio=PAPER_STEERING_RATIO, config=short, seed=3)
    assert a == b and a.duration == 5.0


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"runs": 0}, "runs must be an integer >= 1"),
        ({"runs": 2.5}, "runs must be an integer >= 1"),
        ({"speed": SpeedProfile(target_speed=20.0, pedal_noise=0.3)}, "pedal_noise must be 0"),
    ],
)
def test_bad_arguments_are_named(kwargs: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        lane_keeping_check(load_model("generalized"), **kwargs)


# ------------------------------------------------ the tools that give the estimator a model
SAMPLE = Path(__file__).resolve().parent.parent / "recordings" / "sample"


def test_require_lane_keeping_names_the_model_and_what_it_did() -> None:
    assert require_lane_keeping(load_model("generalized"), steering_ratio=15.0).passed
    # the paper's two-point preset oscillates with a growing amplitude at 15 m/s here
    with pytest.raises(ValueError, match=r"'two-point \(paper\)'.* drives off the road in 4 of 4"):
        require_lane_keeping(load_model("two-point"), steering_ratio=15.0)


def test_the_advisor_task_refuses_a_model_that_cannot_keep_a_lane() -> None:
    with pytest.raises(ConfigError, match="set 'estimator.lane_check' to false"):
        gym.make(ADVISOR, config={"estimator": {"steering_model": "two-point"}})
    env = gym.make(
        ADVISOR, config={"estimator": {"steering_model": "two-point", "lane_check": False}}
    )
    env.reset(seed=0)
    env.close()
    # only the mixture estimator reads the lane from the model
    gym.make(ADVISOR, config={"estimator": {"steering_model": "two-point", "type": "oracle"}})


def test_hasa_replay_refuses_the_estimator_with_such_a_model(
    capsys: pytest.CaptureFixture[str],
) -> None:
    argv = [str(SAMPLE), "--model", "two-point", "--estimator"]
    assert replay_main(argv) == EXIT_USAGE
    err = capsys.readouterr().err
    assert "drives off the road" in err and "--no-lane-check" in err
    assert replay_main([*argv, "--no-lane-check"]) in (0, 1)
    assert "estimator: lateral RMSE" in capsys.readouterr().out


def test_hasa_drive_checks_its_estimator_model_before_the_countdown() -> None:
    probe = LaneKeepingEnv()
    with pytest.raises(ValueError, match="--estimator 'two-point'.*drives off the road"):
        estimator_for("two-point", probe)
    assert callable(estimator_for("two-point", probe, lane_check=False))
    assert callable(estimator_for("generalized", probe))
