"""Every optional campaign key the engine reads can be sent through the API."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from service.api.schemas import CampaignCreate
from service.engine import spec as engine_spec

CONTRACT_FIELDS = set(CampaignCreate.model_fields)


def test_every_key_parse_spec_reads_is_accepted_by_the_api() -> None:
    source = Path(engine_spec.__file__).read_text()
    read = set(re.findall(r'spec\.get\("([a-z_0-9]+)"', source)) | set(engine_spec.RUN_TUNING_KEYS)
    assert read - CONTRACT_FIELDS <= engine_spec.TUNING_KEYS, read - CONTRACT_FIELDS - (
        engine_spec.TUNING_KEYS)
    body = {"rig": "sim", "sensor": "SN-1", "gradient_lag_s": 40.0, "tempco_ug_per_c": 100.0}
    assert CampaignCreate.model_validate(body).model_dump()["gradient_lag_s"] == 40.0


def test_a_typo_is_still_refused() -> None:
    with pytest.raises(ValueError, match="gradient_lag"):
        CampaignCreate.model_validate({"rig": "sim", "sensor": "SN-1", "gradient_lag": 40.0})


def test_tuning_keys_reach_the_stability_config() -> None:
    run = engine_spec.parse_spec({"gradient_lag_s": 40.0, "step_tol_c": 1.5, "odr_hz": 125})
    assert run.stability.gradient_lag_s == 40.0 and run.stability.step_tol_c == 1.5
    assert run.odr_hz == 125.0
