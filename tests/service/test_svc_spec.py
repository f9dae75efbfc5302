"""The campaign spec: one typed model (calibration/campaign_spec.py), every engine key typed,
bounded, defaulted once and used; the API body, the engine's view and the plan read it."""

from __future__ import annotations

import dataclasses

import pytest
from pydantic import ValidationError

from calibration.campaign_spec import TUNING_KEYS, CampaignSpec
from service.api.schemas import CampaignCreate
from service.engine.spec import RunSpec, parse_spec

# A valid, non-default value for every tuning key. The first test keeps this table equal to
# the model's fields, the second proves each value changes what the runner reads: a key
# the engine ignores (or a field added without wiring it through) fails here.
NON_DEFAULT = {
    "stability": "fixed", "min_soak_min": 3.0, "max_soak_min": 99.0, "on_max_soak": "fail",
    "tol_c": 0.7, "dwell_min": 2.0, "die_tol_c": 0.2, "temp_budget_c": 0.5,
    "tempco_ug_per_c": 80.0, "drift_budget": 0.5, "gradient_lag_s": 40.0, "step_tol_c": 1.5,
    "edge_tol_c": 0.4, "expected_sd_g": 5e-4, "max_span_c": 0.5, "temp_noise_c": 0.3,
    "ramp_c_per_min": 3.0, "soak_poll_s": 20.0, "soak_probe_samples": 16, "settle_s": 2.0,
    "move_timeout_s": 60.0, "safe_c": 25.0, "range_g": 4, "odr_hz": 125.0,
    "retry_attempts": 2, "retry_backoff_s": 0.5, "suspend_poll_s": 10.0,
    "suspend_limit_s": 600.0, "rate_gain": "measured", "chamber_band_c": 3.0,
    "suspend_clear_s": 20.0,
    "position_order": "balanced", "position_order_seed": 9,
}


def test_the_table_covers_every_tuning_key() -> None:
    assert set(NON_DEFAULT) == TUNING_KEYS


@pytest.mark.parametrize("key", sorted(NON_DEFAULT))
def test_every_tuning_key_reaches_the_runner(key: str) -> None:
    default = dataclasses.asdict(parse_spec({}))
    tuned = dataclasses.asdict(parse_spec({key: NON_DEFAULT[key]}))
    assert tuned != default, f"{key} is accepted but changes nothing the engine reads"


def test_the_api_body_is_the_engine_spec() -> None:
    body = {"rig": "sim", "sensor": "SN-1", "setpoints_c": [-10, 20], "odr_hz": 125}
    created = CampaignCreate.model_validate(body)
    assert isinstance(created, CampaignSpec)
    run = parse_spec(created.model_dump(exclude_none=True))
    assert run.setpoints_c == [-10.0, 20.0] and run.odr_hz == 125.0
    assert run.extra == {"rig": "sim", "sensor": "SN-1"}


@pytest.mark.parametrize(
    ("key", "value"),
    [
        ("setpoints_c", [False, True]),  # booleans are not numbers
        ("soak_min", True),
        ("samples_per_position", 200000),  # the bridge's maximum is 100000
        ("samples_per_position", 0),
        ("samples_per_position", 20.5),
        ("ramp_c_per_min", "fast"),
        ("ramp_c_per_min", -1),  # 0 is a step (a soak's), below 0 nothing
        ("stability", "bogus"),
        ("on_max_soak", "explode"),
        ("tol_c", -1),
        ("settle_s", 1e9),  # held the rig for minutes in the audit
        ("range_g", 3),  # ADXL355: ±2, ±4, ±8 g
        ("odr_hz", 1e6),
        ("setpoints_c", []),
        ("positions", "table1/../x"),
        ("gradient_lag", 40.0),  # a typo of a tuning key
    ],
)
def test_bad_values_are_refused_naming_the_field(key: str, value: object) -> None:
    with pytest.raises(ValidationError) as info:
        CampaignCreate.model_validate({"rig": "sim", "sensor": "SN-1", key: value})
    assert key in {str(e["loc"][0]) for e in info.value.errors()}


def test_a_stored_spec_with_a_bad_value_is_refused_by_the_engine_too() -> None:
    with pytest.raises(ValueError, match="samples_per_position"):
        parse_spec({"samples_per_position": 200000})


def test_the_engine_view_has_no_default_of_its_own() -> None:
    # A default written on RunSpec would be a second one (the old RunSpec said "travel"
    # while the plan's spec said "table"); every value comes from the one spec.
    assert [f.name for f in dataclasses.fields(RunSpec)
            if f.default is not dataclasses.MISSING
            or f.default_factory is not dataclasses.MISSING] == []
    run, spec = parse_spec({}), CampaignSpec()
    assert (run.position_order, spec.position_order) == ("travel", "travel")
    assert run.ramp_c_per_min == spec.ramp_c_per_min == 1.0
    assert run.stability.max_soak_s == spec.max_soak_s == 2 * 60.0 * 60.0
    assert run.method == "soak"


def test_sensors_are_typed_and_one_sensor_is_a_list_of_one() -> None:
    one = parse_spec(CampaignCreate.model_validate({"rig": "sim", "sensor": "SN-1"}).stored())
    assert one.sensors == ("SN-1",)
    body = {"rig": "sim", "sensors": ["SN-2", "SN-1"]}
    several = CampaignCreate.model_validate(body)
    assert several.sensors == ("SN-2", "SN-1") and several.serials == ["SN-2", "SN-1"]
    assert several.stored()["sensors"] == ["SN-2", "SN-1"]  # stored as JSON
    assert parse_spec(several.stored()).sensors == ("SN-2", "SN-1")
    for bad, why in ((["SN-1", "SN-1"], "named twice"), (["a/b"], "pattern"), ([], "at least")):
        with pytest.raises(ValidationError, match=why) as info:
            CampaignCreate.model_validate({"rig": "sim", "sensors": bad})
        assert info.value.errors()[0]["loc"][0] == "sensors"
    with pytest.raises(ValueError, match="named twice"):
        parse_spec({"sensors": ["SN-1", "SN-1"]})  # a stored spec is checked the same way


def test_the_spec_is_immutable_and_the_plan_reads_it_as_given() -> None:
    from calibration.campaign_plan import Acquire, SetChamber, campaign_plan
    from calibration.schedules import table1

    spec = CampaignSpec(setpoints_c=(-10, 20), samples_per_position=50, ramp_c_per_min=2.5,
                        position_order="table")
    with pytest.raises(ValidationError, match="frozen"):
        spec.soak_min = 1.0  # type: ignore[misc]
    msgs = list(campaign_plan(spec, table1()))
    assert [m.ramp_c_per_min for m in msgs if isinstance(m, SetChamber)] == [2.5, 2.5]
    assert {m.n_samples for m in msgs if isinstance(m, Acquire)} == {50}
    with pytest.raises(ValidationError, match="samples_per_position"):
        CampaignSpec(samples_per_position=200000)  # the simulator's spec is checked too
