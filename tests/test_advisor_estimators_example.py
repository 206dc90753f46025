"""examples/advisor_estimators.py (docs/design.md §12.4-12.5) counts an episode for a lane only
when the estimator decided it: a refused episode back at the prior's 0.5 / 0.5 is refused, not
the true lane its argmax (index 0) happens to be, and an undecided one is undecided."""

from __future__ import annotations

from types import ModuleType

import numpy as np
import pytest
from _programs import load_example

from estimators.evidence import refusal_reasons

THRESHOLD = 0.95  # FilterSettings.decision_threshold's default


def _example() -> ModuleType:
    return load_example("advisor_estimators")


def test_a_refused_tie_is_not_counted_as_the_true_lane() -> None:
    """The case found with the human driving: three episodes of fit:generalized sent back to
    the prior by the reversal rule, one of them with the true lane at index 0 (the old count,
    ``argmax(weights) == true_index``, called it the true lane)."""
    module = _example()
    weights = np.array([0.5, 0.5])
    assert int(np.argmax(weights)) == 0  # what the old count compared with the true lane
    assert module.episode_outcome("model_mismatch", weights, 0, THRESHOLD, 1) == (
        "refused",
        "reversal rule",
    )
    assert module.episode_outcome("model_mismatch", weights, 1, THRESHOLD, 2) == (
        "refused",
        "path rule",
    )
    assert module.episode_outcome("model_mismatch", weights, 0, THRESHOLD) == (
        "refused",
        "mismatch test",
    )


def test_an_undecided_episode_leaning_the_right_way_is_undecided() -> None:
    module = _example()
    assert module.episode_outcome("undecided", [0.92, 0.08], 0, THRESHOLD) == ("undecided", "")


def test_a_decided_episode_counts_for_its_lane() -> None:
    module = _example()
    assert module.episode_outcome("decided", [0.999, 0.001], 0, THRESHOLD) == ("true lane", "")
    assert module.episode_outcome("decided", [0.999, 0.001], 1, THRESHOLD) == ("wrong lane", "")
    assert module.episode_outcome("decided", [0.01, 0.02, 0.97], 2, THRESHOLD) == (
        "true lane",
        "",
    )


def test_weights_frozen_on_a_wrong_lane_count_as_wrong_in_any_state() -> None:
    """As hasa-bench's ``wrong_lane_confident``: the mismatch test freezes the weights, and a run
    frozen confidently on a wrong lane is not hidden among the refusals."""
    module = _example()
    assert module.episode_outcome("model_mismatch", [0.03, 0.97], 0, THRESHOLD) == (
        "wrong lane",
        "",
    )
    assert module.episode_outcome("model_mismatch", [0.97, 0.03], 0, THRESHOLD) == (
        "refused",
        "mismatch test",
    )


def test_an_unknown_decision_state_is_an_error() -> None:
    with pytest.raises(ValueError, match="unknown decision state"):
        _example().episode_outcome("maybe", [0.5, 0.5], 0, THRESHOLD)


def test_the_tally_counts_every_outcome_and_names_the_refusals() -> None:
    module = _example()
    outcomes = [
        module.episode_outcome("decided", [1.0, 0.0], 0, THRESHOLD),
        module.episode_outcome("model_mismatch", [0.5, 0.5], 0, THRESHOLD, 1),
        module.episode_outcome("model_mismatch", [0.5, 0.5], 1, THRESHOLD, 1),
        module.episode_outcome("model_mismatch", [0.5, 0.5], 0, THRESHOLD, 0),
        module.episode_outcome("undecided", [0.6, 0.4], 0, THRESHOLD),
    ]
    counts, why = module.tally(outcomes)
    assert counts == {"true lane": 1, "wrong lane": 0, "undecided": 1, "refused": 3}
    assert why == "mismatch test 1, reversal rule 2"
    assert module.tally([]) == ({"true lane": 0, "wrong lane": 0, "undecided": 0, "refused": 0}, "")


def test_refusal_reasons_name_only_the_runs_in_model_mismatch() -> None:
    decisions = np.array(["model_mismatch", "model_mismatch", "model_mismatch", "decided"])
    codes = np.array([0, 1, 2, 0])
    assert refusal_reasons(decisions, codes).tolist() == [
        "mismatch test",
        "reversal rule",
        "path rule",
        "",
    ]
    assert refusal_reasons(decisions, None).tolist() == ["mismatch test"] * 3 + [""]


@pytest.mark.slow
def test_the_example_prints_the_four_outcomes(capsys) -> None:
    assert _example().main(["--models", "generalized", "--episodes", "1"]) == 0
    header, row = capsys.readouterr().out.splitlines()
    assert header.split()[4:12] == "true lane wrong lane undecided refused gated steering".split()
    cells = row.split()
    assert cells[0] == "generalized" and cells[2:6] == ["1/1", "0/1", "0/1", "0/1"]
