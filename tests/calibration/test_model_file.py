"""Model JSON document: round trip, atomic save, and field-naming errors on bad documents."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import numpy as np
import pytest
import thermal_sim

from calibration.errors import ModelFileError
from calibration.model_file import dump_model_dict, load_model, load_model_dict, save_model
from calibration.thermal import fit_campaign


@pytest.fixture(scope="module")
def model_and_rec() -> tuple:
    _, rec = thermal_sim.campaign(seed=11)
    return fit_campaign(rec).model, rec


def test_round_trip_through_json_text_gives_the_same_compensation(model_and_rec: tuple) -> None:
    model, rec = model_and_rec
    doc = json.loads(json.dumps(dump_model_dict(model), allow_nan=False))
    back = load_model_dict(doc)
    T = rec.temperature_c()
    np.testing.assert_array_equal(back.compensate(rec.raw_g, T), model.compensate(rec.raw_g, T))
    assert back.valid_c == model.valid_c and back.mode == model.mode
    assert back.degree == 3 and len(back.steps) == 11
    np.testing.assert_array_equal(back.steps[4].params, model.steps[4].params)
    assert dump_model_dict(back) == doc


def test_document_has_the_documented_header_units_and_provenance(model_and_rec: tuple) -> None:
    model, _ = model_and_rec
    doc = dump_model_dict(model)
    assert (doc["format"], doc["version"], doc["model_version"]) == (
        "soakcal-model", 2, "sfem-cubic-1")
    comp = doc["temperature"]["compensation"]
    assert comp["per_step"]["enabled"] is True
    assert comp["otherwise"] == doc["temperature"]["streaming_filter"]
    assert doc["temperature"]["streaming_filter"]["tau_s"] == 600.0
    assert doc["polynomial"]["physical_units"]["bx"] == ["g", "g/degC", "g/degC^2", "g/degC^3"]
    assert doc["provenance"]["rows"] == 264 and doc["provenance"]["mode"] == "reference"
    assert doc["extensions"] == []
    # physical coefficients evaluate to the same parameter as the scaled ones
    T = 37.0
    phys = np.array(doc["polynomial"]["physical_coefficients"]["sz"])
    dT = T - doc["temperature"]["centre_c"]
    assert abs(np.polyval(phys[::-1], dT) - model.params_at(T).scale[2]) < 1e-12


def test_save_and_load_file(tmp_path: Path, model_and_rec: tuple) -> None:
    model, _ = model_and_rec
    path = tmp_path / "sub" / "model.json"
    save_model(path, model)
    assert [p.name for p in path.parent.iterdir()] == ["model.json"]  # no temp file left
    back = load_model(path)
    np.testing.assert_array_equal(back.coeffs, model.coeffs)


def _broken(doc: dict, path: str, value: object) -> dict:
    d = copy.deepcopy(doc)
    *parents, last = path.split(".")
    node = d
    for p in parents:
        node = node[p]
    if value is KeyError:
        del node[last]
    else:
        node[last] = value
    return d


@pytest.mark.parametrize(
    ("path", "value", "field"),
    [
        ("format", "something-else", "format"),
        ("version", 3, "version"),
        ("temperature.compensation.otherwise.tau_s", -1.0,
         "temperature.compensation.otherwise"),
        ("temperature.compensation.per_step.enabled", "yes",
         "temperature.compensation.per_step.enabled"),
        ("model_version", "sfem-quintic-9", "model_version"),
        ("mode", "magic", "mode"),
        ("temperature", KeyError, "temperature"),
        ("temperature.scale_c", 0.0, "temperature.scale_c"),
        ("temperature.valid_c", [60, -40], "temperature.valid_c"),
        ("polynomial.degree", "3", "polynomial.degree"),
        ("polynomial.coefficients.sy", [1.0, 2.0], "polynomial.coefficients.sy"),
        ("polynomial.coefficients.bx", [0.0, None, 0.0, 0.0], "polynomial.coefficients.bx"),
        ("extensions", [{"offset": 1}], "extensions[0].kind"),
        ("identifiable", {"bx": "yes"}, "identifiable"),
    ],
)
def test_bad_documents_are_rejected_naming_the_field(
    model_and_rec: tuple, path: str, value: object, field: str
) -> None:
    doc = dump_model_dict(model_and_rec[0])
    with pytest.raises(ModelFileError) as info:
        load_model_dict(_broken(doc, path, value))
    assert f"'{field}'" in str(info.value)


def test_version_1_documents_still_load_with_the_default_conditioning(
    model_and_rec: tuple,
) -> None:
    from calibration.model_file import load_conditioning_dict

    model, rec = model_and_rec
    doc = dump_model_dict(model)
    doc["version"] = 1
    del doc["temperature"]["compensation"], doc["temperature"]["streaming_filter"]
    back = load_model_dict(doc)
    T = rec.temperature_c()
    np.testing.assert_array_equal(back.compensate(rec.raw_g, T), model.compensate(rec.raw_g, T))
    cond = load_conditioning_dict(doc)
    assert cond.per_step and cond.tau_s == 600.0


def test_bad_files_name_the_file(tmp_path: Path) -> None:
    with pytest.raises(ModelFileError, match="not found"):
        load_model(tmp_path / "missing.json")
    p = tmp_path / "bad.json"
    p.write_text("{not json")
    with pytest.raises(ModelFileError, match="bad.json"):
        load_model(p)
    p.write_text("[1, 2]")
    with pytest.raises(ModelFileError, match="JSON object"):
        load_model(p)


def test_twin_round_trips_and_bad_rig_or_noise_fields_are_named(
    tmp_path: Path, model_and_rec: tuple
) -> None:
    from calibration.discrepancy.twin_file import (
        Twin,
        load_model_or_twin,
        save_twin,
        twin_from_dict,
    )

    model, _ = model_and_rec
    twin = Twin(model, die_tau_s=120.0, noise_sd_g=[1e-5, 2e-5, 3e-5], temperature_noise_c=0.02,
                sample_sd_g=[1e-4, 1e-4, 2e-4], samples_per_reading=40.0, air_tau_s=90.0,
                ramp_c_per_min=2.0, die_tau_sd_s=15.0)
    save_twin(tmp_path / "twin.json", twin)
    back = load_model_or_twin(tmp_path / "twin.json")
    assert back.to_dict() == twin.to_dict()
    # a model file read as a twin: the same physics, the rig unknown
    save_model(tmp_path / "m.json", model)
    assert load_model_or_twin(tmp_path / "m.json").die_tau_s is None
    for section, key, value in [("rig", "die_tau_s", -1.0), ("rig", "air_tau_s", None),
                                ("rig", "ramp_c_per_min", 0), ("rig", "die_tau_sd_s", "x"),
                                ("noise", "sd_g", [1.0, 2.0]), ("noise", "sample_sd_g", [-1, 0, 0]),
                                ("noise", "temperature_c", float("inf")),
                                ("noise", "samples_per_reading", 0.5)]:
        doc = twin.to_dict()
        doc[section][key] = value
        with pytest.raises(ModelFileError, match=rf"^{section}\.{key}: expected"):
            twin_from_dict(doc)
    with pytest.raises(ModelFileError, match="nope.json: model or twin file not found"):
        load_model_or_twin(tmp_path / "nope.json")
