"""examples/live_share_by_start_speed.py (issue 25's live-share bar at start speeds 15-45 m/s;
docs/design.md §8.28) runs and gives one row per seed and start speed."""

from __future__ import annotations

import numpy as np
from _programs import load_example

SHARES = ("live", "off", "unused", "mismatch", "tempered_model_error", "tempered_autocorrelation")


def test_one_row_per_start_speed_with_shares_that_add_up(capsys) -> None:
    module = load_example("live_share_by_start_speed")
    table = module.main(["--seeds", "8300", "--speeds", "15,45", "--runs", "1"])
    assert list(table["start_speed"]) == [15.0, 45.0] and set(table["seed"]) == {8300}
    assert "tempered_autocorrelation" in capsys.readouterr().out
    np.testing.assert_allclose(table[list(SHARES)].sum(axis=1), 1.0, atol=1e-9)
    assert table["mean_speed"].iloc[1] > 40.0  # the run started at 45 m/s stays fast
    assert (table["lateral_rmse"] > 0).all() and (table["lateral_rmse"] < 0.5).all()
