"""``lever_arm``: centripetal acceleration off the rotation axis (effects.md)."""

from calibration.discrepancy.effects.not_identifiable import Unobservable

LEVER_ARM = Unobservable(
    effect_id="lever_arm", confusers=("filter_delay",), needs_motion=True,
    why="it acts only while the table rotates (∝ ω²); every reading here is static",
    experiment="record during constant-rate rotations at two or more rates (e.g. 60 and 120 °/s)",
)
