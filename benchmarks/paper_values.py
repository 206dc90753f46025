"""The paper's published numbers (Mai et al., table 1 in section 3.3.1, table 2 in 4.3.2,
curved track in 3.3.2),
printed beside ours for comparison. Ours are what the code measures; nothing
is tuned toward these.
"""

from __future__ import annotations

DRIVERS = ("Ill", "1", "2", "3", "4", "5", "6", "7", "8")

# Table 1: steering prediction, per driver: (two-point RMSE rad, two-point R^2 "Acc",
# generalized RMSE rad, generalized R^2 "Acc", RMSE decrease).
TABLE_1 = {
    "Ill": (0.005, 0.084, 7e-4, 0.974, 0.87),
    "1": (0.006, 0.091, 5e-4, 0.9311, 0.92),
    "2": (0.0082, 0.047, 0.0014, 0.942, 0.82),
    "3": (0.0076, 0.007, 5e-4, 0.926, 0.94),
    "4": (0.0033, -0.033, 9e-4, 0.865, 0.73),
    "5": (0.0055, 0.062, 4e-4, 0.904, 0.92),
    "6": (0.004, -0.063, 9e-4, 0.938, 0.74),
    "7": (0.0087, -0.022, 7e-4, 0.967, 0.92),
    "8": (0.0095, 0.032, 0.0023, 0.939, 0.75),
}

# Table 2: lateral estimation RMSE (m) of the mixture estimate, mean and std over
# runs: (two-point mean, two-point std, generalized mean, generalized std).
# The paper labels the std column "m^2"; it is in metres (docs/design.md §10).
TABLE_2 = {
    "Ill": (1.0, 0.06, 0.22, 0.11),
    "1": (1.0, 0.11, 0.18, 0.04),
    "2": (0.95, 0.11, 0.21, 0.10),
    "3": (0.97, 0.18, 0.25, 0.15),
    "4": (0.98, 0.17, 0.18, 0.06),
    "5": (0.95, 0.11, 0.17, 0.06),
    "6": (1.0, 0.15, 0.18, 0.05),
    "7": (0.93, 0.17, 0.25, 0.15),
    "8": (0.96, 0.11, 0.18, 0.06),
}

# Section 4.3.2: curved track, illustrative participant: (R^2, RMSE rad).
CURVED = {"generalized": (0.665, 0.089), "two_point": (-0.141, 0.546)}

# No-steering baseline (section 4.3.2): "the mean error is 0.9 m".
NO_STEERING_LATERAL_RMSE = 0.9
