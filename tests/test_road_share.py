"""benchmarks.road_share: the road-blind AR(2) against the generalized model, per archetype."""

import numpy as np
import pytest

from benchmarks.road_share import _seeds, archetype_table, driver_scores, main
from hasa_env.drivers import POPULATIONS, population


def test_the_table_has_one_line_per_archetype_with_the_median_share():
    rows = [
        {"archetype": kind, "road_share": share, "sdlp": 0.25, "off_road": 0, "runs": 2,
         "road_blind": np.array([0.9, 0.8]), "generalized": np.array([0.95, 0.85])}
        for kind, share in (("noisy-corrections", 0.1), ("preview", 0.02),
                            ("noisy-corrections", 0.3), ("noisy-corrections", 0.2))
    ]  # fmt: skip
    lines = archetype_table(rows).splitlines()
    assert len(lines) == 4 and lines[2].startswith("| preview | 1 |")  # archetypes' order
    noisy = lines[3].split(" | ")
    assert noisy[:4] == ["| noisy-corrections", "3", "0.850", "0.900"]
    assert noisy[4].startswith("0.200 [0.100, 0.300]") and noisy[5] == "3/3"
    assert noisy[7] == "0/6 runs |"
    assert _seeds("2500,2502-2504") == [2500, 2502, 2503, 2504]


@pytest.mark.slow
def test_driver_scores_fit_and_score_every_driver_on_its_held_out_runs(capsys):
    params = population("mixed", 0, 4)  # one driver of each archetype
    config = dict(POPULATIONS["mixed"].env_config) | {"time_limit": 6.0}
    rows = driver_scores(params, config, train_seed=0, test_seeds=[1, 2])
    assert [r["driver"] for r in rows] == [p.name for p in params]
    assert {r["archetype"] for r in rows} == set(POPULATIONS["mixed"].archetypes)
    for r in rows:
        assert r["road_blind"].shape == r["generalized"].shape == (2,)
        assert np.all(r["road_blind"] < 1.0) and r["road_share"] <= 1.0
        assert r["off_road"] == 0 and 0.05 < r["sdlp"] < 0.6 and r["runs"] == 2
    assert main(["--seeds", "0", "--size", "4", "--train-seed", "0", "--test-seeds", "1",
                 "--duration", "4"]) == 0  # fmt: skip
    assert capsys.readouterr().out.count("\n") == 6


def test_bad_seeds_are_a_usage_error_naming_the_option(capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["--seeds", "nope"])
    assert exit_info.value.code == 2
    assert "--seeds" in capsys.readouterr().err
