"""Rendering: the driver's-eye view, the HUD with hypothesis weights, the paced human window."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from hasa_env.envs.lane_keeping import LaneKeepingEnv
from hasa_env.render import TopDownRenderer, make_renderer
from hasa_env.render.common import (
    GRASS_COLOUR,
    HYPOTHESIS_COLOURS,
    MARKING_COLOUR,
    ROAD_COLOUR,
    HumanWindow,
    resolve_weights,
    surface_to_array,
)
from hasa_env.render.driver_view import (
    FAR_POINT_COLOUR,
    GHOST_FADED_COLOUR,
    NEAR_POINT_COLOUR,
    SKY_COLOUR,
    DriverViewRenderer,
)
from hasa_env.sim.setup import build_setup


def _mask(frame: np.ndarray, colour: tuple[int, int, int], tol: int = 2) -> np.ndarray:
    return np.all(np.abs(frame.astype(int) - np.array(colour)) <= tol, axis=-1)


def _info(config: dict | None = None, **options) -> tuple[object, dict]:
    env = LaneKeepingEnv(config=config)
    _, info = env.reset(seed=0, options=options or None)
    return env.setup, info


def test_driver_view_shows_sky_road_markings_and_ghost_markings():
    setup, info = _info({"render": {"width": 640, "height": 360}}, bias_index=0)
    frame = DriverViewRenderer(setup, "rgb_array").render(info)
    assert frame.shape == (360, 640, 3) and frame.dtype == np.uint8
    horizon = int(0.4 * 360)
    sky = _mask(frame, SKY_COLOUR)
    assert sky[:horizon].mean() > 0.8 and sky[horizon + 2 :].sum() == 0
    road = _mask(frame, ROAD_COLOUR)
    assert road[horizon:].mean() > 0.3  # the road fills much of the view below the horizon
    assert road[:horizon].sum() == 0  # and none of the sky
    white = _mask(frame, MARKING_COLOUR, tol=3)
    assert white[horizon:].sum() > 1000
    ghost = _mask(frame, GHOST_FADED_COLOUR)
    assert ghost.sum() > 300  # the -1.8 m hypothesis' markings
    assert _mask(frame, GRASS_COLOUR)[horizon:].sum() > 0


def test_no_ghost_markings_without_a_wrong_hypothesis():
    setup, info = _info(
        {"markings": {"hypotheses": [0.0]}, "render": {"width": 640, "height": 360}}
    )
    frame = DriverViewRenderer(setup, "rgb_array").render(info)
    assert _mask(frame, GHOST_FADED_COLOUR).sum() == 0
    assert _mask(frame, MARKING_COLOUR, tol=3).sum() > 1000


@pytest.mark.parametrize(("bias_index", "lines"), [(1, [0.0, 3.6]), (0, [-3.6, 0.0])])
def test_ghost_markings_sit_where_the_other_hypothesis_puts_the_lane(
    bias_index: int, lines: list[float]
) -> None:
    # camera reads y + b: hypothesis b_i puts the centre at y = b_i - b; with b = -1.8 the
    # ghost (b_i = 0) is 1.8 m left, with b = 0 the ghost (b_i = -1.8) is 1.8 m right
    setup, info = _info(
        {"markings": {"hypotheses": [0.0, -1.8]}}, lateral_offset=0.0, bias_index=bias_index
    )
    view = DriverViewRenderer(setup, "rgb_array")
    frame = view.render(info)
    assert sorted(view.ghost_lines) == pytest.approx(lines)
    assert view.ghost_centres == pytest.approx([sum(lines) / 2])
    # with the car centred in its lane, the ghost line at y = 0 runs straight ahead (screen centre)
    ghost = _mask(frame, GHOST_FADED_COLOUR)
    cols = np.flatnonzero(ghost[int(0.75 * view.height)])
    if cols.size:  # a dash may be in a gap at that row; check where there is one
        assert abs(cols.mean() - view.width / 2) < 0.05 * view.width
    rows, cols = np.nonzero(ghost[int(view.horizon) + 5 :])
    assert cols.size and abs(np.median(cols) - view.width / 2) < 0.1 * view.width


def test_perspective_projection_geometry():
    setup, info = _info(lateral_offset=0.0)
    view = DriverViewRenderer(setup, "rgb_array", size=(800, 450))
    camera = view._camera(info)
    X, Y, _ = setup.road.pose_at(np.array([info["station"] + 1.2 + 20.0]))
    sx, sy, forward = view.project(X, Y, camera)
    assert forward[0] == pytest.approx(20.0)
    assert sx[0] == pytest.approx(400.0)
    assert sy[0] == pytest.approx(view.horizon + view.focal * view.eye_height / 20.0)
    assert view.focal == pytest.approx(400.0 / math.tan(0.6))
    # the car 0.5 m right of the lane centre sees the lane centre left of the screen centre
    _, info_right = _info(lateral_offset=-0.5)
    camera = view._camera(info_right)
    sx, _, _ = view.project(X, Y, camera)
    assert sx[0] == pytest.approx(400.0 - view.focal * 0.5 / 20.0)


def test_near_and_far_points_are_drawn_only_when_asked():
    setup, info = _info({"render": {"width": 640, "height": 360}})
    plain = DriverViewRenderer(setup, "rgb_array").render(info)
    shown = DriverViewRenderer(setup, "rgb_array", show_points=True).render(info)
    assert _mask(plain, NEAR_POINT_COLOUR).sum() == 0 and _mask(plain, FAR_POINT_COLOUR).sum() == 0
    assert _mask(shown, NEAR_POINT_COLOUR).sum() > 50 and _mask(shown, FAR_POINT_COLOUR).sum() > 5


def test_driver_view_on_the_curved_track_follows_the_bend():
    env = LaneKeepingEnv(config={"track": "curved", "action": {"type": "physical"}})
    _, info = env.reset(seed=0)
    while info["station"] < 250.0:  # into the first (left) bend
        steer = (
            math.atan(2.8 * info["road_curvature"])
            - 0.05 * info["lateral_offset"]
            - 0.5 * info["heading"]
        )
        _, _, _, _, info = env.step([steer, 0.0])
    view = DriverViewRenderer(env.setup, "rgb_array", size=(640, 360))
    frame = view.render(info)
    road = _mask(frame, ROAD_COLOUR)
    band = road[int(view.horizon) + 3 : int(view.horizon) + 20]
    cols = np.nonzero(band)[1]
    assert cols.size and cols.mean() < 320  # a left bend: the far road lies left of centre


def test_hud_shows_the_hypothesis_weights():
    setup, info = _info({"render": {"width": 640, "height": 360}})
    view = DriverViewRenderer(setup, "rgb_array")
    plain = view.render(info)
    with_weights = view.render(info, weights=[0.25, 0.75])
    bar = _mask(with_weights, HYPOTHESIS_COLOURS[1], tol=0)
    assert bar.sum() > 50 and _mask(plain, HYPOTHESIS_COLOURS[1], tol=0).sum() == 0
    # the 0.75 bar is three times the 0.25 bar
    bar0 = _mask(with_weights[:200, :400], HYPOTHESIS_COLOURS[0], tol=0) & ~_mask(
        plain[:200, :400], HYPOTHESIS_COLOURS[0], tol=0
    )
    assert bar.sum() == pytest.approx(3 * bar0.sum(), rel=0.15)
    # taken from info when an estimator wrapper put them there
    from_info = view.render({**info, "estimate_weights": [0.25, 0.75]})
    assert np.array_equal(from_info, with_weights)


def test_resolve_weights_sources():
    info = {"estimate_weights": np.array([0.9, 0.1])}
    hyps = (0.0, -1.8)
    assert resolve_weights(None, info, hyps) == [(0.0, 0.9), (-1.8, 0.1)]
    assert resolve_weights({-1.8: 1.0}, info, hyps) == [(-1.8, 1.0)]
    assert resolve_weights(lambda i: [0.5, 0.5], info, hyps) == [(0.0, 0.5), (-1.8, 0.5)]
    assert resolve_weights(None, {}, hyps) is None
    info2 = {"estimator_weights": [0.2, 0.3, 0.5], "estimator_hypotheses": [0.0, -1.8, 1.8]}
    assert resolve_weights(None, info2, hyps)[2] == (1.8, 0.5)
    with pytest.raises(ValueError, match="3 hypothesis weights for 2 hypotheses"):
        resolve_weights([0.2, 0.3, 0.5], {}, hyps)


def test_env_config_selects_the_view_and_top_down_still_renders():
    setup = build_setup({"render": {"view": "driver", "width": 320, "height": 240}})
    assert isinstance(make_renderer(setup, "rgb_array"), DriverViewRenderer)
    assert isinstance(make_renderer(setup, "rgb_array", view="top_down"), TopDownRenderer)
    with pytest.raises(ValueError, match="unknown view"):
        make_renderer(setup, "rgb_array", view="bird")
    setup, info = _info()
    frame = TopDownRenderer(setup, "rgb_array", weights=[0.5, 0.5]).render(info)
    plain = TopDownRenderer(setup, "rgb_array").render(info)
    assert frame.shape == (480, 640, 3)
    bar = (
        _mask(frame, HYPOTHESIS_COLOURS[1], tol=0).sum()
        - _mask(plain, HYPOTHESIS_COLOURS[1], tol=0).sum()
    )
    assert bar > 20


def test_human_window_is_paced_by_the_simulation_clock():
    import pygame

    window = HumanWindow(pygame, (64, 64), fps=30, caption="test")
    start = time.perf_counter()
    assert window.frame_due(0.0)
    frames = 0
    for k in range(1, 21):  # 0.2 s of simulation at 100 Hz
        if window.frame_due(k * 0.01):
            frames += 1
            window._last_frame = time.perf_counter()
    elapsed = time.perf_counter() - start
    assert elapsed >= 0.19  # real time, not as fast as possible
    assert 4 <= frames <= 8  # about 30 frames per second of simulated time, not one per step


def test_driver_view_human_mode_opens_a_window_headless():
    setup, info = _info({"render": {"width": 160, "height": 120}})
    view = DriverViewRenderer(setup, "human")
    assert view.render(info) is None
    assert view._window.window is not None
    view.close()


def test_hud_shows_the_weights_an_estimator_wrapper_puts_in_info():
    wrappers = pytest.importorskip("estimators.wrappers")
    from estimators.gm_ekf import GaussianMixtureEKF
    from estimators.settings import FilterSettings
    from hasa_env.steering import GeneralizedModel

    env = LaneKeepingEnv(
        config={"render": {"width": 640, "height": 360}, "action": {"type": "physical"}}
    )
    ekf = GaussianMixtureEKF(
        GeneralizedModel.paper().arx(), FilterSettings.from_env_config(env.config), dt=0.01
    )
    wrapped = wrappers.EstimatorInfoWrapper(env, ekf)
    _, info = wrapped.reset(seed=0)
    for _ in range(20):
        _, _, _, _, info = wrapped.step([0.0, 0.0])
    weights = np.asarray(info["estimate_weights"])
    assert weights.shape == (2,)
    view = DriverViewRenderer(env.setup, "rgb_array")
    shown = view.render(info)
    expected = view.render(info, weights=list(weights))
    assert np.array_equal(shown, expected)  # the HUD found them in info by itself
    plain = view.render({k: v for k, v in info.items() if not k.startswith("estimate_")})
    assert not np.array_equal(shown, plain)


def test_env_render_honours_the_render_view_config():
    import gymnasium as gym

    env = gym.make(
        "hasa_env/LaneKeeping-v0",
        render_mode="rgb_array",
        config={"render": {"view": "driver", "width": 320, "height": 180}},
    )
    env.reset(seed=0)
    frame = env.render()
    assert _mask(frame, SKY_COLOUR)[:60].mean() > 0.5


def test_participant_view_hides_ghosts_and_hud_and_adds_bonnet_and_road_texture():
    from hasa_env.render import ViewOptions
    from hasa_env.render.driver_view import BONNET_COLOUR, GRASS_BAND_COLOUR, ROAD_BAND_COLOUR

    setup, info = _info({"render": {"width": 640, "height": 360}}, bias_index=1)
    info = {**info, "estimate_weights": [0.25, 0.75]}
    developer = DriverViewRenderer(setup, "rgb_array").render(info)
    view = DriverViewRenderer(setup, "rgb_array", options=ViewOptions.participant())
    frame = view.render(info)
    # the developer's view has the ghost markings, the HUD panel and the weight bars
    assert _mask(developer, GHOST_FADED_COLOUR).sum() > 300
    assert _mask(developer, HYPOTHESIS_COLOURS[1], tol=0).sum() > 50
    # the participant's: none of them; the top-left corner is plain sky
    assert _mask(frame, GHOST_FADED_COLOUR).sum() == 0
    assert _mask(frame, HYPOTHESIS_COLOURS[1], tol=0).sum() == 0
    assert _mask(frame[:60, :200], SKY_COLOUR).all()
    # a bonnet at the bottom centre, where the road is in the developer's view
    assert _mask(frame[-40:-30, 280:360], BONNET_COLOUR).all()
    assert _mask(developer[-40:-30, 280:360], BONNET_COLOUR).sum() == 0
    # lighter bands on the road and the grass, which move as the car drives on
    road_bands = _mask(frame, ROAD_BAND_COLOUR)
    assert road_bands.sum() > 1000 and _mask(frame, GRASS_BAND_COLOUR).sum() > 1000
    later = view.render({**info, "station": info["station"] + 2.0})
    assert not np.array_equal(_mask(later, ROAD_BAND_COLOUR), road_bands)
    # messages (instructions, countdown) are still drawn without a HUD
    with_message = surface_to_array(view.draw(info, message="3\nrun 1 of 10"))
    assert not np.array_equal(with_message, frame)


def test_view_options_choose_hud_items_and_refuse_unknown_ones():
    import pygame

    from hasa_env.render import ViewOptions
    from hasa_env.render.common import Hud

    hud = Hud(pygame, 360, 30.0, items=("speed",))
    assert hud.lines({"time": 1.0, "speed": 15.0, "steering": 0.01}) == [
        "speed 15.00 m/s  ( 54.0 km/h)"
    ]
    # the steering line leads with the angle a person turns: 0.05 deg of road wheel is
    # 0.8 deg of steering wheel (15:1 unless the wheel's profile says otherwise)
    steering = {"time": 1.0, "speed": 15.0, "steering": math.radians(0.05)}
    assert Hud(pygame, 360, items=("steering",)).lines(steering) == [
        "wheel   +0.8 deg (road +0.05)"
    ]
    assert Hud(pygame, 360, steering_ratio=10.0, items=("steering",)).lines(steering) == [
        "wheel   +0.5 deg (road +0.05)"
    ]
    assert ViewOptions.from_dict({"hud": ["time", "weights"]}).hud == ("time", "weights")
    with pytest.raises(ValueError, match="unknown item 'clock'; allowed: time, speed"):
        ViewOptions(hud=("clock",))
    with pytest.raises(ValueError, match="unknown view option 'ghost'; allowed: ghosts"):
        ViewOptions.from_dict({"ghost": False})
    with pytest.raises(ValueError, match="'bonnet' must be true or false"):
        ViewOptions(bonnet="yes")  # type: ignore[arg-type]
    # the top-down view honours the ghost option too
    setup, info = _info({"render": {"width": 320, "height": 240}})
    from hasa_env.render.common import GHOST_COLOUR

    shown = TopDownRenderer(setup, "rgb_array").render(info)
    hidden = TopDownRenderer(setup, "rgb_array", options=ViewOptions(ghosts=False)).render(info)
    assert _mask(shown, GHOST_COLOUR, 0).sum() > 0 and _mask(hidden, GHOST_COLOUR, 0).sum() == 0


def _frame_at_station(
    scenario: str, view: str, station: float, bias_index: int = 1
) -> tuple[np.ndarray, dict, object]:
    """A ``render_mode="rgb_array"`` frame of ``scenario`` with the car driven straight,
    on the marked lane's centre, to ``station`` (m); true bias ``hypotheses[bias_index]``
    (1: -1.8 m, under which a shift toward the other hypothesis goes left)."""
    import gymnasium as gym

    env = gym.make(
        "hasa_env/LaneKeeping-v0",
        render_mode="rgb_array",
        config={"scenario": scenario, "render": {"view": view, "width": 640, "height": 360}},
    )
    options = {"lateral_offset": 0.0, "heading": 0.0, "steering": 0.0, "speed": 30.0}
    _, info = env.reset(seed=0, options={**options, "bias_index": bias_index})
    while info["station"] < station:
        _, _, terminated, _, info = env.step(np.zeros(2, np.float32))
        assert not terminated
    return env.render(), info, env.unwrapped.setup


def _columns_near(row: np.ndarray, expected: list[float], tol: float) -> None:
    """Yellow pixels of ``row`` lie near each ``expected`` column (px), and only there."""
    cols = np.flatnonzero(row)
    assert cols.size, "no yellow pixels in the row"
    for x in expected:
        assert np.min(np.abs(cols - x)) <= tol, (x, cols)
    nearest = np.min(np.abs(cols[:, None] - np.array(expected)[None, :]), axis=1)
    assert nearest.max() <= tol + 3, (expected, cols)


def test_the_driven_lane_of_a_lane_shift_is_drawn_in_yellow_in_both_views():
    from hasa_env.render import ViewOptions
    from hasa_env.render.common import DRIVEN_LANE_COLOUR

    station, width, height = 180.0, 640, 360
    # driver's view: the row showing the road 10 m ahead of the eye
    frame, info, setup = _frame_at_station("lane_shift", "driver", station)
    plain, *_ = _frame_at_station("paper", "driver", station)
    assert info["lateral_offset"] == 0.0 and info["heading"] == 0.0
    yellow = _mask(frame, DRIVEN_LANE_COLOUR, tol=0)
    assert yellow.sum() > 1000 and _mask(plain, DRIVEN_LANE_COLOUR, tol=0).sum() == 0
    assert _mask(frame, MARKING_COLOUR, tol=3).sum() > 1000  # the white markings stay
    rc = setup.config["render"]
    focal = 0.5 * width / math.tan(0.5 * rc["horizontal_field_of_view"])
    horizon = 0.4 * height
    row = int(round(horizon + focal * rc["eye_height"] / 10.0))
    ahead = focal * rc["eye_height"] / (row + 0.5 - horizon)  # m ahead of the eye at the row
    centre = float(setup.road.driven_offset(info["station"] + 1.2 + ahead, info["bias"]))
    assert 0.8 < centre < 1.4  # mid-shift: the driven lane is well off the marked one
    expected = [0.5 * width - focal * (centre + side) / ahead for side in (-1.8, 1.8)]
    _columns_near(yellow[row], expected, tol=3.0)
    # the participant follows it too: drawn without ghosts and HUD
    view = DriverViewRenderer(setup, "rgb_array", options=ViewOptions.participant())
    assert _mask(view.render(info), DRIVEN_LANE_COLOUR, tol=0).sum() > 1000
    # top-down: the road 10 m ahead of the car's station, the car's station at 70 % height
    frame, info, setup = _frame_at_station("lane_shift", "top_down", station)
    plain, *_ = _frame_at_station("paper", "top_down", station)
    yellow = _mask(frame, DRIVEN_LANE_COLOUR, tol=0)
    assert _mask(plain, DRIVEN_LANE_COLOUR, tol=0).sum() == 0
    ppm = setup.config["render"]["pixels_per_metre"]
    row = int(round(0.7 * height - 10.0 * ppm))
    centre = float(setup.road.driven_offset(info["station"] + 10.0, info["bias"]))
    _columns_near(yellow[row], [0.5 * width - (centre + s) * ppm for s in (-1.8, 1.8)], 2.0)
    # before the shift's start (150 m) the driven lane is the marked one: no yellow there
    early = TopDownRenderer(setup, "rgb_array").render({**info, "station": 156.0})
    yellow = _mask(early, DRIVEN_LANE_COLOUR, tol=0)
    before, after = (int(round(0.7 * height - (s - 156.0) * ppm)) for s in (148.0, 165.0))
    assert yellow[before].sum() == 0 and yellow[after].sum() > 0


def test_the_filled_near_and_far_points_sit_on_the_driven_lane():
    setup = build_setup({"scenario": "lane_shift", "render": {"width": 640, "height": 360}})
    info = {"time": 6.0, "station": 180.0, "lateral_offset": 0.0, "heading": 0.0,
            "speed": 30.0, "steering": 0.0, "bias": -1.8}  # fmt: skip
    from hasa_env.render import ViewOptions

    options = ViewOptions(ghosts=False)  # no ghost rings: the filled point alone
    view = DriverViewRenderer(setup, "rgb_array", show_points=True, options=options)
    near = _mask(view.render(info), NEAR_POINT_COLOUR)
    ahead = 6.2 - 1.2  # the near point is 6.2 m ahead of the station, the eye 1.2 m
    expected = 320.0 - view.focal * float(setup.road.driven_offset(186.2, -1.8)) / ahead
    assert expected < 260.0  # well left of the marked lane's centre (320 px)
    assert abs(np.nonzero(near)[1].mean() - expected) < 3.0
