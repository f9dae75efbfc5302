"""Allowed campaign state transitions: one table, used by the API (409) and the runner."""

from __future__ import annotations

STATES = ("queued", "running", "paused", "completed", "failed", "aborted")
TERMINAL = frozenset({"completed", "failed", "aborted"})
PHASES = ("ramp", "soak", "positions", "fitting")

# action -> states in which the action is legal
ACTIONS: dict[str, frozenset[str]] = {
    "pause": frozenset({"queued", "running"}),
    "resume": frozenset({"paused"}),
    "abort": frozenset({"queued", "running", "paused"}),
}

# (from, to) pairs the runner and API may write
TRANSITIONS: frozenset[tuple[str, str]] = frozenset(
    {
        ("queued", "running"),
        ("queued", "paused"),
        ("queued", "aborted"),
        ("queued", "failed"),  # cannot start: the rig cannot be opened, the spec is unusable
        ("running", "paused"),
        ("running", "completed"),
        ("running", "failed"),
        ("running", "aborted"),
        ("paused", "running"),
        ("paused", "queued"),
        ("paused", "aborted"),
    }
)

# action -> {from state: to state} when no engine holds the campaign (the API writes it
# directly); a held campaign gets ``requested_action`` and its engine moves it.
UNHELD_TARGETS: dict[str, dict[str, str]] = {
    "pause": {"queued": "paused"},  # the manager skips it; it does not hold the rig
    "resume": {"paused": "queued"},  # picked up again from its measurements
    "abort": {"queued": "aborted", "paused": "aborted"},
}
assert all((a, b) in TRANSITIONS for m in UNHELD_TARGETS.values() for a, b in m.items())


class IllegalTransition(Exception):
    """An action that the campaign's current state does not allow (HTTP 409)."""

    def __init__(self, action: str, state: str) -> None:
        allowed = ", ".join(sorted(ACTIONS.get(action, ())))
        super().__init__(
            f"cannot {action} a campaign in state '{state}' (allowed from: {allowed or 'none'})"
        )
        self.action = action
        self.state = state


def check_action(action: str, state: str) -> None:
    if action not in ACTIONS:
        raise ValueError(f"unknown action {action!r}; expected one of {sorted(ACTIONS)}")
    if state not in ACTIONS[action]:
        raise IllegalTransition(action, state)
