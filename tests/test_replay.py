"""hasa-replay: replay checks (and where they diverge), scores, frames; the shipped sample."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from _recording_files import tamper

from hasa_cli.replay import main
from hasa_env.recording import check_replay, load_recording
from hasa_env.recording.raw_inputs import load_raw_inputs
from hasa_env.recording.reader import load_paths

SAMPLE = Path(__file__).resolve().parent.parent / "recordings" / "sample"


def _copy_sample(tmp_path: Path) -> Path:
    target = tmp_path / "sample"
    shutil.copytree(SAMPLE, target)
    return target / "run_000.csv"


def test_the_shipped_sample_is_a_labelled_synthetic_30_s_drive_that_replays():
    rec = load_recording(SAMPLE / "run_000.csv")
    assert rec.complete and rec.steps == 3000 and rec.meta["end_reason"] == "truncated"
    meta = rec.meta["metadata"]
    assert meta["synthetic"] is True and meta["tool"] == "hasa-drive"
    assert "virtual joystick" in meta["synthetic_driver"]["description"]
    assert rec.data["speed"].iloc[0] == 15.0 and rec.data["lateral_offset"].iloc[0] == -0.5
    assert rec.data["bias"].iloc[0] == -1.8
    raw = load_raw_inputs(SAMPLE / "run_000.csv")
    assert len(raw) == 3000 and raw["source"].str.contains("G29").all()
    assert np.array_equal(raw["road_wheel_angle"].to_numpy(), rec.data["steering"].to_numpy()[1:])
    # bit for bit with this platform's libm; a tolerance keeps the check meaningful elsewhere
    assert check_replay(rec, atol=1e-9).matches


def test_hasa_replay_reports_a_match(capsys):
    assert main([str(SAMPLE)]) == 0
    out = capsys.readouterr().out
    assert "run_000.csv: synthetic, 3000 steps: replay matches the recording" in out


def test_hasa_replay_says_where_a_tampered_recording_diverges(tmp_path, capsys):
    csv = _copy_sample(tmp_path)
    lines = csv.read_text().split("\n")
    header = lines[0].split(",")
    col = header.index("lateral_offset")
    fields = lines[1 + 1500].split(",")  # row 1500 is on line 1502 (1 = header)
    fields[col] = repr(float(fields[col]) + 1e-6)
    lines[1 + 1500] = ",".join(fields)
    csv.write_text("\n".join(lines))
    assert main([str(csv)]) == 1
    out = capsys.readouterr().out
    assert "DIVERGES at row 1500 (t = 15.00 s), column 'lateral_offset'" in out
    rec = load_recording(csv)
    check = check_replay(rec)
    assert check.divergence[:2] == (1500, "lateral_offset")
    assert check.divergence[2] == pytest.approx(check.divergence[3] + 1e-6)
    assert check_replay(rec, atol=1e-5).matches


def test_hasa_replay_detects_a_changed_action(tmp_path, capsys):
    csv = _copy_sample(tmp_path)
    tamper(csv, 700, "steering", 1e-3)
    assert main([str(tmp_path)]) == 1
    out = capsys.readouterr().out
    # row k's steering is the action over the step that ended at row k: replaying the tampered
    # action changes the state of that very row (station is the first column that depends on it)
    assert "DIVERGES at row 700 (t = 7.00 s), column 'station'" in out


def test_hasa_replay_reports_load_errors(tmp_path, capsys):
    csv = _copy_sample(tmp_path)
    csv.with_suffix(".json").unlink()
    assert main([str(csv)]) == 2
    assert "missing sidecar" in capsys.readouterr().err
    assert main([str(tmp_path / "nothing_here")]) == 2
    recs = load_paths([tmp_path])
    assert list(recs) == [] and len(recs.errors) == 1


def test_hasa_replay_writes_frames_with_road_and_ghost_markings(tmp_path, capsys):
    from hasa_env.render.driver_view import GHOST_FADED_COLOUR

    out_dir = tmp_path / "frames"
    code = main(
        [str(SAMPLE), "--frames", str(out_dir), "--frame-every", "1000", "--size", "320x180"]
    )
    assert code == 0
    frames = sorted(out_dir.glob("frame_*.png"))
    assert [f.name for f in frames] == [
        "frame_00000.png",
        "frame_01000.png",
        "frame_02000.png",
        "frame_03000.png",
    ]
    import pygame

    image = pygame.surfarray.array3d(pygame.image.load(str(frames[1]))).transpose(1, 0, 2)
    assert image.shape == (180, 320, 3)
    road = np.all(np.abs(image.astype(int) - np.array([90, 90, 96])) <= 2, axis=-1)
    ghost = np.all(np.abs(image.astype(int) - np.array(GHOST_FADED_COLOUR)) <= 2, axis=-1)
    assert road.mean() > 0.15 and ghost.sum() > 20


def test_hasa_replay_video_is_optional(tmp_path, capsys):
    video = tmp_path / "drive.gif"
    code = main([str(SAMPLE), "--video", str(video), "--frame-every", "1500", "--size", "128x72"])
    captured = capsys.readouterr()
    try:
        import imageio  # noqa: F401
    except ImportError:  # said at once, before any work, as an environment problem
        assert code == 3 and not video.exists() and captured.out == ""
        assert captured.err.startswith("hasa-replay: error: --video needs imageio")
    else:  # pragma: no cover - imageio is not a dependency
        assert code == 0 and video.exists()


def test_hasa_replay_scores_a_fitted_steering_model(capsys):
    def scores(*extra):
        assert main([str(SAMPLE), "--model", "two-point", "--fit", *extra]) == 0
        out = capsys.readouterr().out
        line = next(ln for ln in out.splitlines() if "model two-point:" in ln and "rmse" in ln)
        return float(line.split("rmse ")[1].split(",")[0]), float(
            line.split("r2 ")[1].split(",")[0]
        )

    rmse, r2 = scores("--steering", "applied")
    assert 0 < rmse < 1e-3 and r2 > 0.9
    measured_rmse, _ = scores()  # the default: the steering sensor's reading, noisier
    assert measured_rmse > rmse


@pytest.mark.parametrize(
    "argv, says",
    [
        (["--model", "two-pont"], "did you mean 'two-point'?"),
        (["--model", "no_such_module_here:Model", "--estimator"], "no_such_module_here"),
        (["--model", "missing.json"], "missing.json"),
    ],
)
def test_a_model_that_cannot_load_refuses_the_run_before_any_replay(argv, says, capsys):
    """Exit 2 means nothing was done (README): a misspelt model refuses the run before the
    recordings are replayed, not after."""
    assert main([str(SAMPLE), *argv]) == 2
    out, err = capsys.readouterr()
    assert "replay" not in out, out
    assert err.startswith("hasa-replay: error: ") and says in err, err


@pytest.mark.slow
def test_hasa_replay_runs_the_estimator_and_it_finds_the_true_lane(capsys):
    pytest.importorskip("estimators.gm_ekf")
    argv = [str(SAMPLE), "--model", "two-point", "--fit", "--steering", "applied", "--estimator"]
    assert main(argv) == 0
    out = capsys.readouterr().out
    line = next(ln for ln in out.splitlines() if "estimator:" in ln)
    assert "lateral RMSE" in line
    final_true = float(line.split("-1.8 m: ")[1].split("]")[0])
    assert final_true > 0.9  # the sample's true bias is -1.8 m


def test_paper_presets_are_scored_in_steering_wheel_units(capsys):
    from hasa_env.steering.loading import default_steering_ratio, in_model_units

    assert default_steering_ratio("generalized", fitted=False) == 15.0
    assert default_steering_ratio("generalized", fitted=True) == 1.0
    assert default_steering_ratio("my_model.json", fitted=False) == 1.0
    rec = load_recording(SAMPLE / "run_000.csv")
    scaled = in_model_units(rec.data, 15.0)
    assert np.array_equal(scaled["steering"], rec.data["steering"] * 15.0)
    assert np.array_equal(scaled["lateral_offset"], rec.data["lateral_offset"])

    def r2(argv):
        assert main([str(SAMPLE), "--model", "generalized", *argv]) == 0
        line = next(
            ln for ln in capsys.readouterr().out.splitlines() if "model generalized: rmse" in ln
        )
        return float(line.split("r2 ")[1].split(",")[0])

    # the paper's generalized coefficients describe the steering-wheel angle (ratio 15)
    assert r2([]) > 0.5
    assert r2(["--steering-ratio", "1"]) < 0.1


def test_replay_accepts_every_start_that_reset_accepts(tmp_path):
    """Replay passes row 0 as reset options within reset's own limits (+-30 m, +-pi/2 rad)."""
    import gymnasium as gym

    from hasa_env.recording import RecordingWrapper, check_replay, load_recording

    config = {"road": {"lanes_left": 5, "lane_width": 6.0}, "time_limit": 0.5}
    env = RecordingWrapper(gym.make("hasa_env/LaneKeeping-v0", config=config), tmp_path)
    env.reset(seed=4, options={"lateral_offset": 21.5, "heading": 1.3})
    for _ in range(50):
        env.step(np.zeros(2, dtype=np.float32))
    env.close()
    rec = load_recording(env.path)
    assert rec.data["lateral_offset"].iloc[0] == 21.5 and rec.data["heading"].iloc[0] == 1.3
    assert check_replay(rec).matches


def test_the_curvature_limit_follows_what_the_model_was_fitted_on(tmp_path):
    import math

    import pandas as pd

    from estimators.settings import STRAIGHT_CURVATURE, model_curvature_limit
    from hasa_env.steering import GeneralizedModel, SteeringModel
    from hasa_env.steering.fitting import training_curvature

    paper = GeneralizedModel.paper()  # fitted on the paper's straight track
    assert model_curvature_limit(paper) == STRAIGHT_CURVATURE
    path = tmp_path / "model.json"
    paper.save(path)
    assert SteeringModel.load(path).training_curvature == 0.0  # kept in the file
    assert model_curvature_limit(GeneralizedModel()) == math.inf  # unfitted: unknown
    curved = pd.DataFrame({"road_curvature": [0.0, 1 / 150, -1 / 120]})
    assert training_curvature(curved) == 1 / 120
    assert training_curvature(pd.DataFrame({"station": [0.0, 300.0]})) == 0.0  # straight
