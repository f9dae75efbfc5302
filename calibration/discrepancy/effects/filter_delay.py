"""``filter_delay``: timestamp lag of the digital filter (effects.md)."""

from calibration.discrepancy.effects.not_identifiable import Unobservable

FILTER_DELAY = Unobservable(
    effect_id="filter_delay", confusers=("lever_arm",), needs_motion=True,
    why=("it acts only while the table rotates (∝ ω, sign flips with direction); "
         "readings are static"),
    experiment="record continuous rotations in both directions and compare the tangential error",
)
