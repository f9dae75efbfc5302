"""``local_gravity``: the local g is not 1 g (effects.md)."""

from calibration.discrepancy.effects.not_identifiable import Unobservable

LOCAL_GRAVITY = Unobservable(
    effect_id="local_gravity", confusers=("scale_nonlinearity",),
    why=("a common relative scale error on all axes is exactly a different |g|: every static "
         "tumble absorbs it into the three scale factors"),
    experiment="use the local g from a gravity survey (or a gravimeter) as the reference magnitude",
)
