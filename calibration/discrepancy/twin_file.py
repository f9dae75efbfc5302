"""The twin document (``docs/diagnosis.md`` §9): a calibration model plus the rig and noise.

``{"format": "soakcal-twin", "version": 1, "model": <soakcal-model document>,
"rig": {"die_tau_s": float | null, "die_tau_sd_s": float | null, "air_tau_s": float,
"ramp_c_per_min": float},
"noise": {"sd_g": [3] | null, "temperature_c": float | null, "sample_sd_g": [3] | null,
"samples_per_reading": float | null}, "effects": [...], "provenance": {...}}``

The ``model`` member is an ordinary model file (``docs/model-file.md``), so a twin holds the
same sensor physics (SFEM, seed Eq. 1, with cubic parameters, Eq. 8) that ``calibrate``
writes. ``diagnose --against`` accepts either document; ``--write-twin`` writes this one and
``soakcal sim --twin`` loads it.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from calibration.errors import ModelFileError
from calibration.model_file import FORMAT as MODEL_FORMAT
from calibration.model_file import dump_model_dict, load_json_document, load_model_dict
from calibration.recording import atomic_write_text
from calibration.thermal import ThermalModel
from calibration.thermal_plant import DEFAULT_AIR_TAU_S, DEFAULT_RAMP_C_PER_MIN

TWIN_FORMAT = "soakcal-twin"
TWIN_VERSION = 1


@dataclass
class Twin:
    """A sensor model with the rig and noise it was seen through."""

    model: ThermalModel
    die_tau_s: float | None = None  # die lag behind the recorded air temperature (None: unknown)
    noise_sd_g: list[float] | None = None  # per-axis sd of one averaged reading, g
    temperature_noise_c: float | None = None  # rms of the temperature channel per reading, °C
    effects: list[dict[str, Any]] = field(default_factory=list)
    provenance: dict[str, Any] = field(default_factory=dict)
    sample_sd_g: list[float] | None = None  # per-axis sd of one raw sample (sd_* columns), g
    samples_per_reading: float | None = None  # median n of the recording
    # The chamber's response (calibration/discrepancy/rig.py): not identifiable from plateau
    # readings alone, so a fitted twin keeps the rig's nominal values and says so.
    air_tau_s: float = DEFAULT_AIR_TAU_S
    ramp_c_per_min: float = DEFAULT_RAMP_C_PER_MIN
    die_tau_sd_s: float | None = None  # σ of die_tau_s (profile), None: not estimated

    def to_dict(self) -> dict[str, Any]:
        return {
            "format": TWIN_FORMAT, "version": TWIN_VERSION,
            "model": dump_model_dict(self.model),
            "rig": {"die_tau_s": self.die_tau_s, "die_tau_sd_s": self.die_tau_sd_s,
                    "air_tau_s": self.air_tau_s,
                    "ramp_c_per_min": self.ramp_c_per_min},
            "noise": {"sd_g": self.noise_sd_g, "temperature_c": self.temperature_noise_c,
                      "sample_sd_g": self.sample_sd_g,
                      "samples_per_reading": self.samples_per_reading},
            "effects": list(self.effects),
            "provenance": dict(self.provenance),
        }


def save_twin(path: str | os.PathLike, twin: Twin) -> None:
    atomic_write_text(path, json.dumps(twin.to_dict(), indent=2, allow_nan=False) + "\n")


def load_model_or_twin(path: str | os.PathLike) -> Twin:
    """Read a model file or a twin file; a model file becomes a twin with an unknown rig."""
    return load_json_document(path, twin_from_dict, "model or twin")


def twin_from_dict(doc: Any) -> Twin:
    if not isinstance(doc, dict):
        raise ModelFileError("expected a JSON object")
    fmt = doc.get("format")
    if fmt == MODEL_FORMAT:
        return Twin(load_model_dict(doc))
    if fmt != TWIN_FORMAT:
        raise ModelFileError(f"format: expected {MODEL_FORMAT!r} or {TWIN_FORMAT!r}, got {fmt!r}")
    if doc.get("version") != TWIN_VERSION:
        raise ModelFileError(f"version: this soakcal reads twin version {TWIN_VERSION}, "
                             f"got {doc.get('version')!r}")
    try:
        model = load_model_dict(doc.get("model"))
    except ModelFileError as exc:
        raise ModelFileError(f"model.{exc}") from None
    rig = doc.get("rig") or {}
    noise = doc.get("noise") or {}
    # Each field is checked the same way: null (unknown) where allowed, else a finite
    # number above its floor; the message names the field as "<section>.<key>".
    tau = _opt_number(rig, "rig", "die_tau_s", 0.0)
    sd = _opt_triple(noise, "noise", "sd_g")
    tn = _opt_number(noise, "noise", "temperature_c", 0.0)
    ssd = _opt_triple(noise, "noise", "sample_sd_g")
    spr = _opt_number(noise, "noise", "samples_per_reading", 1.0)
    air_tau = _number(rig, "rig", "air_tau_s", DEFAULT_AIR_TAU_S, 0.0)
    ramp = _number(rig, "rig", "ramp_c_per_min", DEFAULT_RAMP_C_PER_MIN, 0.0, strict=True)
    tau_sd = _opt_number(rig, "rig", "die_tau_sd_s", 0.0)
    effects = doc.get("effects") or []
    if not isinstance(effects, list) or not all(isinstance(e, dict) for e in effects):
        raise ModelFileError("effects: expected a list of objects")
    from calibration.discrepancy.twin_effects import check_effects

    check_effects(effects)
    return Twin(model, die_tau_s=tau, noise_sd_g=sd, temperature_noise_c=tn, effects=effects,
                provenance=dict(doc.get("provenance") or {}), sample_sd_g=ssd,
                samples_per_reading=spr, air_tau_s=air_tau, ramp_c_per_min=ramp,
                die_tau_sd_s=tau_sd)


def _number(section: dict[str, Any], where: str, key: str, default: float, floor: float,
            *, strict: bool = False) -> float:
    """``section[key]`` (``default`` when absent) as a float >= floor (> floor if strict)."""
    v = section.get(key, default)
    if not (_is_num(v) and (v > floor if strict else v >= floor)):
        raise ModelFileError(f"{where}.{key}: expected a number {'>' if strict else '>='} "
                             f"{floor:g}, got {v!r}")
    return float(v)


def _opt_number(section: dict[str, Any], where: str, key: str, floor: float) -> float | None:
    """``section[key]`` as None (unknown) or a float >= floor."""
    v = section.get(key)
    if v is not None and not (_is_num(v) and v >= floor):
        raise ModelFileError(f"{where}.{key}: expected null or a number >= {floor:g}, "
                             f"got {v!r}")
    return None if v is None else float(v)


def _opt_triple(section: dict[str, Any], where: str, key: str) -> list[float] | None:
    """``section[key]`` as None (unknown) or three numbers >= 0 (one per axis)."""
    v = section.get(key)
    if v is not None and not (isinstance(v, list) and len(v) == 3
                              and all(_is_num(x) and x >= 0 for x in v)):
        raise ModelFileError(f"{where}.{key}: expected null or three numbers >= 0, got {v!r}")
    return None if v is None else [float(x) for x in v]


def _is_num(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and bool(np.isfinite(v))
