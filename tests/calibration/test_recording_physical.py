"""The recording reader refuses what cannot be physical, naming line, column and fix."""

from __future__ import annotations

import numpy as np
import pytest

from calibration.errors import RecordingError
from calibration.recording import _plateaus, parse_recording

HEADER = "t_s,step,position,chamber_c,ax,ay,az,n,sd_x,sd_y,sd_z"
GOOD = ["0,0,0,25.0,0.0,0.0,1.0,100,0.001,0.001,0.001",
        "10,0,1,25.0,1.0,0.0,0.0,100,0.001,0.001,0.001"]


def _with(line2: str) -> str:
    return "\n".join([HEADER, GOOD[0], line2]) + "\n"


@pytest.mark.parametrize(
    ("row", "column", "words"),
    [
        ("10,0,1,25.0,1.0,0.0,0.0,100,1e30,0.001,0.001", "sd_x",
         "standard deviation 1e+30 g is beyond the sensor's range ±8 g"),
        ("10,-1,1,25.0,1.0,0.0,0.0,100,0.001,0.001,0.001", "step",
         "step = -1: a step index is a whole number ≥ 0"),
        ("10,1.5,1,25.0,1.0,0.0,0.0,100,0.001,0.001,0.001", "step",
         "step = 1.5: a step index is a whole number ≥ 0"),
        ("10,0,-7,25.0,1.0,0.0,0.0,100,0.001,0.001,0.001", "position",
         "position = -7: a position index is a whole number ≥ 0"),
        ("1e308,0,1,25.0,1.0,0.0,0.0,100,0.001,0.001,0.001", "t_s",
         "t_s = 1e+308 s is not a time in seconds"),
    ],
)
def test_unphysical_cells_are_refused_with_line_and_column(row: str, column: str,
                                                           words: str) -> None:
    with pytest.raises(RecordingError) as err:
        parse_recording(_with(row), "rec.csv")
    msg = str(err.value)
    assert msg.startswith(f"rec.csv:3: column '{column}': ")
    assert words in msg
    assert msg.count("rec.csv") == 1


def test_a_plain_recording_still_reads() -> None:
    rec = parse_recording("\n".join([HEADER, *GOOD]) + "\n", "rec.csv")
    assert len(rec) == 2


def test_plateaus_in_linear_time_give_the_running_mean_rule() -> None:
    rng = np.random.default_rng(0)
    t = np.r_[np.full(300, 20.0), np.linspace(20, 30, 400), np.full(300, 60.0)]
    t = t + rng.normal(0, 0.3, t.size)
    expected = np.zeros(t.size, int)  # the rule, written the slow way
    start, k = 0, 0
    for i in range(1, t.size):
        if abs(t[i] - np.mean(t[start:i])) > 2.0:
            k, start = k + 1, i
        expected[i] = k
    np.testing.assert_array_equal(_plateaus(t), expected)
