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
from pathlib import Path
from typing import Any

import numpy as np

from calibration.discrepancy.rig import DEFAULT_AIR_TAU_S, DEFAULT_RAMP_C_PER_MIN
from calibration.errors import ModelFileError
from calibration.model_file import FORMAT as MODEL_FORMAT
from calibration.model_file import dump_model_dict, load_model_dict
from calibration.recording import atomic_write_text
from calibration.thermal import ThermalModel

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
    p = Path(path)
    try:
        doc = json.loads(p.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ModelFileError(f"{p}: file not found") from None
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ModelFileError(f"{p}: not a JSON model or twin file ({exc})") from None
    try:
        return twin_from_dict(doc)
    except ModelFileError as exc:
        raise ModelFileError(f"{p}: {exc}") from None


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
    tau = rig.get("die_tau_s")
    if tau is not None and not (_is_num(tau) and tau >= 0):
        raise ModelFileError(f"rig.die_tau_s: expected null or a number >= 0, got {tau!r}")
    sd = noise.get("sd_g")
    if sd is not None and not (isinstance(sd, list) and len(sd) == 3
                               and all(_is_num(v) and v >= 0 for v in sd)):
        raise ModelFileError(f"noise.sd_g: expected null or three numbers >= 0, got {sd!r}")
    tn = noise.get("temperature_c")
    if tn is not None and not (_is_num(tn) and tn >= 0):
        raise ModelFileError(f"noise.temperature_c: expected null or a number >= 0, got {tn!r}")
    ssd = noise.get("sample_sd_g")
    if ssd is not None and not (isinstance(ssd, list) and len(ssd) == 3
                                and all(_is_num(v) and v >= 0 for v in ssd)):
        raise ModelFileError(f"noise.sample_sd_g: expected null or three numbers >= 0, "
                             f"got {ssd!r}")
    spr = noise.get("samples_per_reading")
    if spr is not None and not (_is_num(spr) and spr >= 1):
        raise ModelFileError(f"noise.samples_per_reading: expected null or a number >= 1, "
                             f"got {spr!r}")
    air_tau = rig.get("air_tau_s", DEFAULT_AIR_TAU_S)
    if not (_is_num(air_tau) and air_tau >= 0):
        raise ModelFileError(f"rig.air_tau_s: expected a number >= 0, got {air_tau!r}")
    ramp = rig.get("ramp_c_per_min", DEFAULT_RAMP_C_PER_MIN)
    if not (_is_num(ramp) and ramp > 0):
        raise ModelFileError(f"rig.ramp_c_per_min: expected a number > 0, got {ramp!r}")
    tau_sd = rig.get("die_tau_sd_s")
    if tau_sd is not None and not (_is_num(tau_sd) and tau_sd >= 0):
        raise ModelFileError(f"rig.die_tau_sd_s: expected null or a number >= 0, got {tau_sd!r}")
    effects = doc.get("effects") or []
    if not isinstance(effects, list) or not all(isinstance(e, dict) for e in effects):
        raise ModelFileError("effects: expected a list of objects")
    return Twin(model, None if tau is None else float(tau),
                None if sd is None else [float(v) for v in sd],
                None if tn is None else float(tn), effects, dict(doc.get("provenance") or {}),
                None if ssd is None else [float(v) for v in ssd],
                None if spr is None else float(spr), float(air_tau), float(ramp),
                None if tau_sd is None else float(tau_sd))


def _is_num(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and bool(np.isfinite(v))
