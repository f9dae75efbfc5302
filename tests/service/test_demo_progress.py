"""`make demo`'s progress line numbers a step as the recording and the event log do."""

from service.demo import step_line


def test_the_progress_line_names_the_step_as_the_event_log_does():
    entry = {"step": 7, "steps": 11, "setpoint_c": 30.0, "chamber_c": 30.004,
             "soak_s": 2490.0, "reason": "die_predicted_within_tol", "tau_s": 876.0}
    line = step_line(entry, 4.1)
    # the event log says "soak ended … step=7 setpoint_c=30": the same number, 0-based,
    # with the step's place in the campaign beside it
    assert line.startswith("  step  7 (8/11)    30.0 °C  chamber   30.00 °C  soak  41.5 min")
    assert "(die_predicted_within_tol, τ 14.6 min)" in line and line.endswith("[wall   4.1 s]")
