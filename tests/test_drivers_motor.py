"""The output stage every synthetic driver shares: lag, remnant after it, wheel quantization."""

import math

import numpy as np
import pytest
from scipy.signal import butter, filtfilt, welch

from hasa_env.drivers.motor import G29_RESOLUTION, MotorParams, MotorStage, neuromuscular_lag

DT = 0.01


def stage(motors, frequency=10.0, damping=0.7, limit=0.5, seeds=None, dt=DT):
    n = len(motors)
    out = MotorStage(np.full(n, frequency), np.full(n, damping), motors, np.full(n, limit))
    seeds = seeds if seeds is not None else list(range(n))
    out.reset([np.random.default_rng(s) for s in seeds], dt)
    out.start(np.zeros(n))
    return out


def drive(motor_stage, commands):
    return np.array([motor_stage.step(c) for c in commands])


def test_g29_step_and_defaults():
    assert G29_RESOLUTION == pytest.approx(2 * math.pi * 2.5 / 65536)
    assert G29_RESOLUTION == pytest.approx(2.4e-4, rel=0.01)
    assert G29_RESOLUTION / 15.0 == pytest.approx(1.6e-5, rel=0.01)  # at the road wheel
    default = MotorParams()
    assert not default.has_remnant and default.wheel_resolution == 0.0


@pytest.mark.parametrize(("field", "value", "allowed"), [
    ("broadband_std", -1e-4, r"\[0, 0.05\]"),
    ("broadband_time_constant", float("nan"), r"\[0, 10\]"),
    ("tremor_frequency", 0.1, r"\[0.5, 40\]"),
    ("tremor_damping", 0.0, r"\(0, 1\]"),
    ("signal_dependent_gain", 2.0, r"\[0, 1\]"),
    ("steering_ratio", 0.5, r"\[1, 100\]"),
    ("wheel_resolution", -1.0, r"\[0, 0.1\]"),
])  # fmt: skip
def test_motor_params_name_the_bad_field_and_its_range(field, value, allowed):
    with pytest.raises(ValueError, match=rf"MotorParams\.{field} must be in {allowed}"):
        MotorParams(**{field: value})
    with pytest.raises(ValueError, match="unknown fields"):
        MotorParams.from_dict({"tremor": 1.0})
    with pytest.raises(ValueError, match="remnant scale"):
        MotorParams().scaled(-1.0)


def test_without_remnant_the_stage_is_the_exact_lag():
    commands = np.sin(np.arange(300) * 0.05)[:, None] * 0.01
    out = drive(stage([MotorParams()]), commands)[:, 0]
    ad, bd = neuromuscular_lag(10.0, 0.7, DT)
    x = np.zeros(2)
    expected = []
    for u in commands[:, 0]:
        x = ad @ x + bd * u
        expected.append(x[0])
    np.testing.assert_allclose(out, expected, rtol=0, atol=1e-15)
    # the ZOH discretisation settles on the command with unit gain
    assert drive(stage([MotorParams()]), np.full((2000, 1), 0.02))[-1, 0] == pytest.approx(0.02)


def test_remnant_components_have_their_stationary_stds():
    n = 20_000
    zero = np.zeros((n, 1))
    broadband = drive(stage([MotorParams(broadband_std=3e-4, broadband_time_constant=0.15)]), zero)
    assert broadband[:, 0].std() == pytest.approx(3e-4, rel=0.1)
    lag1 = np.corrcoef(broadband[1:, 0], broadband[:-1, 0])[0, 1]
    assert lag1 == pytest.approx(math.exp(-DT / 0.15), abs=0.01)  # OU: rho = exp(-Ts / tau)
    white = drive(stage([MotorParams(broadband_std=2e-4)]), zero)[:, 0]
    assert white.std() == pytest.approx(2e-4, rel=0.05)
    assert abs(np.corrcoef(white[1:], white[:-1])[0, 1]) < 0.02
    tremor = drive(stage([MotorParams(tremor_std=5e-5, tremor_frequency=10.0)]), zero)[:, 0]
    assert tremor[500:].std() == pytest.approx(5e-5, rel=0.1)


def test_signal_dependent_noise_grows_with_the_lag_rate():
    motor = MotorParams(signal_dependent_gain=0.05)
    still = drive(stage([motor]), np.zeros((3000, 1)))[:, 0]
    assert np.all(still == 0.0)  # no movement, no signal-dependent noise
    slow_ramp = np.linspace(0, 0.05, 3000)[:, None]
    fast_ramp = np.linspace(0, 0.5, 3000)[:, None]
    slow = drive(stage([motor]), slow_ramp)[:, 0] - drive(stage([MotorParams()]), slow_ramp)[:, 0]
    fast = drive(stage([motor]), fast_ramp)[:, 0] - drive(stage([MotorParams()]), fast_ramp)[:, 0]
    # the ramps' rates differ 10x (1.67e-3 and 1.67e-2 rad/s): so do the noise stds
    assert fast[500:].std() / slow[500:].std() == pytest.approx(10.0, rel=0.2)
    assert fast[500:].std() == pytest.approx(0.05 * 0.5 / 30.0, rel=0.2)


def test_quantization_puts_the_applied_steering_on_the_wheel_grid():
    motor = MotorParams(broadband_std=3e-4, steering_ratio=15.0, wheel_resolution=G29_RESOLUTION)
    commands = np.linspace(-0.6, 0.6, 4000)[:, None]  # beyond the 0.5 rad limit both ways
    out = drive(stage([motor]), commands)[:, 0]
    steps = out * 15.0 / G29_RESOLUTION
    np.testing.assert_allclose(steps, np.round(steps), rtol=0, atol=1e-6)
    assert np.abs(out).max() <= 0.5 and np.abs(out).max() > 0.5 - G29_RESOLUTION / 15.0
    # a slow noise-free ramp visits every level, one G29 step (1.6e-5 rad) apart
    quiet = MotorParams(wheel_resolution=G29_RESOLUTION)
    slow = drive(stage([quiet]), np.linspace(0.0, 1e-3, 4000)[:, None])[:, 0]
    levels = np.unique(np.round(slow * 15.0 / G29_RESOLUTION))
    assert len(levels) > 50 and np.all(np.diff(levels) == 1.0)


def test_each_car_draws_its_own_noise_alone_or_in_a_batch():
    motors = [
        MotorParams(broadband_std=3e-4, broadband_time_constant=0.1, tremor_std=5e-5,
                    tremor_frequency=9.0, signal_dependent_gain=0.02,
                    wheel_resolution=G29_RESOLUTION),
        MotorParams(broadband_std=1e-4),
        MotorParams(tremor_std=8e-5, tremor_frequency=11.5, tremor_damping=0.15),
    ]  # fmt: skip
    commands = 0.01 * np.sin(np.arange(2500)[:, None] * np.array([0.01, 0.02, 0.03]))
    together = drive(stage(motors, seeds=[7, 8, 9]), commands)
    for i, motor in enumerate(motors):
        alone = drive(stage([motor], seeds=[7 + i]), commands[:, i : i + 1])[:, 0]
        np.testing.assert_array_equal(together[:, i], alone)


def test_tremor_shows_as_a_peak_at_its_frequency():
    motor = MotorParams(broadband_std=2e-4, broadband_time_constant=0.2, tremor_std=6e-5,
                        tremor_frequency=9.3, tremor_damping=0.2)  # fmt: skip
    out = drive(stage([motor]), np.zeros((6000, 1)))[:, 0]
    low = filtfilt(*butter(4, 4.0, fs=1 / DT), out)
    freq, power = welch(out - low, fs=1 / DT, nperseg=512)
    band = freq > 1.0
    assert abs(freq[band][np.argmax(power[band])] - 9.3) < 1.0


def test_a_tremor_above_the_nyquist_frequency_of_the_step_is_left_out():
    motor = MotorParams(tremor_std=6e-5, tremor_frequency=9.0)
    out = drive(stage([motor], dt=0.1), np.zeros((200, 1)))[:, 0]  # a policy acting at 10 Hz
    assert np.all(out == 0.0)
