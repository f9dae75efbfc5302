"""The numbers that decide a calibration's pass or fail, for the dashboard's calibration page.

The calibration row keeps its fit report (``calibration.thermal.fit_campaign``'s
``report``) beside the model document; ``GET /api/v1/calibrations/{id}`` gives
only the model. This reads the report into what a lab engineer checks: the
|g| RMSE (the seed paper's Eq. 9) before and after the thermal model, the
valid range, each step's figures, which SFEM parameters were fitted and which
were held at nominal (not identifiable from the positions), and the
polynomial degree asked for and used. The held-out (leave-one-position-out)
figure needs the fit redone: ``/holdout`` shares the figures' refit.

A step fit's figures are per step (rms over the steps); a continuous (ramp) or
warm-up fit has no steps to average, so its report carries the |g| RMSE of every
fitted row and Table 6 per temperature band (``calibration.ramp_report``), and a
continuous fit's plateaus stand in the step table.
"""

from __future__ import annotations

import math
from typing import Any

from fastapi import APIRouter, Depends, HTTPException, Request
from pydantic import BaseModel, Field

from calibration.warmup import norm_rmse_caveat
from service.api import auth
from service.api.deps import DbIdPath, SessionDep
from service.db.models import Calibration
from service.db.timestamps import as_utc
from service.web.figures import refit_of

router = APIRouter(prefix="/web/calibrations", tags=["dashboard"],
                   dependencies=[Depends(auth.viewer)],
                   responses={404: {"description": "no such calibration"}})


class StepRow(BaseModel):
    step: int
    setpoint_c: float | None
    temperature_c: float | None = Field(description="the step's die temperature the fit used")
    positions: int | None
    rmse_before_ug: float | None = Field(description="|g| error of the raw readings (Eq. 9)")
    rmse_step_fit_ug: float | None = Field(description="after this step's own SFEM fit")
    rmse_after_ug: float | None = Field(description="after the thermal polynomial model")
    chi2_red: float | None
    soak_s: float | None = Field(description="rig seconds the step soaked")
    soak_reason: str | None = Field(description="why the soak ended")


class BandRow(BaseModel):
    lo_c: float
    hi_c: float
    rows: int
    positions: int
    rmse_before_ug: float | None = Field(description="|g| error of the raw readings (Eq. 9)")
    rmse_after_ug: float | None = Field(description="after the calibration")
    legs: dict[str, Any] | None = Field(
        description="heating and cooling legs' mean residuals and whether they agree "
                    "(calibration.ramp_report); None: crossed one way only")


class CalibrationPage(BaseModel):
    id: int
    sensor: str
    campaign_id: int | None
    created_at: Any
    model_version: str
    mode: str | None
    method: str | None
    degree: int | None = Field(description="degree of the thermal polynomials used")
    degree_requested: int | None
    temperature_source: str | None
    valid_c: tuple[float, float]
    rmse_before_ug: float | None = Field(description="raw readings: rms over steps (a step "
                                         "fit), over every fitted row (continuous, warm-up)")
    rmse_after_ug: float | None = Field(
        description="after the model, as rmse_before_ug (a step or continuous fit: the "
                    "calibration's rmse_ug; a warm-up: |g| after its bias-change model)")
    scatter_ug: float | None = Field(description="a warm-up's rmse_ug: each axis' scatter "
                                     "about its orientation's mean after the model")
    heldout_mg_xyz: dict[str, list[float]] | None = Field(
        description="a warm-up's held-out RMS per axis, uncompensated and compensated")
    rmse_caveat: str | None = Field(
        default=None, description="a warm-up's |g| RMSE after: what it is not (the CLI's "
                                  "caveat); None when its orientations identify every bias "
                                  "and scale, and for other fits")
    fitted: list[str] = Field(description="SFEM parameters fitted")
    held: list[str] = Field(description="SFEM parameters held at nominal: the positions "
                            "cannot identify them")
    joint_fit: dict[str, Any] | None
    chi2_red: float | None = Field(description="a continuous fit's reduced chi-square")
    drift_ug_per_k: dict[str, float | None] = Field(
        description="|slope| of the output at fixed orientation vs temperature, before/after")
    steps: list[StepRow]
    bands: list[BandRow] = Field(description="Table 6 per temperature band (continuous, "
                                 "warm-up); empty for a step fit")
    notes: list[str]


@router.get("/{calibration_id}/summary", response_model=CalibrationPage)
def calibration_page(calibration_id: DbIdPath, session: SessionDep) -> CalibrationPage:
    """RMSE before and after, valid range, per-step table, what was fitted and what held."""
    row = session.get(Calibration, calibration_id)
    if row is None:
        raise HTTPException(status_code=404, detail=f"calibration {calibration_id} not found")
    report: dict[str, Any] = row.report or {}
    provenance: dict[str, Any] = row.provenance or {}
    soaks = {s.get("step"): s for s in provenance.get("steps_log") or []}
    # a continuous fit's plateaus are its steps (fitted with every other row: no own fit)
    steps = [_step_row(st, soaks.get(st.get("step"), {}))
             for st in report.get("steps") or report.get("plateaus") or []]
    warmup = report.get("method") == "warmup"
    stepped = bool(report.get("steps"))
    identifiable: dict[str, bool] = report.get("identifiable") or {}
    drift = report.get("drift") or {}
    return CalibrationPage(
        id=row.id, sensor=row.sensor, campaign_id=row.campaign_id,
        created_at=as_utc(row.created_at), model_version=row.model_version,
        mode=report.get("mode"), method=report.get("method"), degree=report.get("degree"),
        degree_requested=(row.model or {}).get("provenance", {}).get("degree_requested"),
        temperature_source=report.get("temperature_source"),
        valid_c=(row.valid_lo_c, row.valid_hi_c),
        rmse_before_ug=(_rms([s.rmse_before_ug for s in steps]) if stepped
                        else _ug(report.get("rmse_before_mg"))),
        rmse_after_ug=_ug(report.get("rmse_after_mg")) if warmup else row.rmse_ug,
        scatter_ug=row.rmse_ug if warmup else None,
        heldout_mg_xyz=report.get("heldout_rms_mg_xyz") if warmup else None,
        rmse_caveat=(norm_rmse_caveat(report, "the held-out RMS per axis below")
                     if warmup else None),
        # a warm-up's report names them itself (it fits only what it identifies)
        fitted=[k for k, ok in identifiable.items() if ok] or list(report.get("fitted") or []),
        held=[k for k, ok in identifiable.items() if not ok] or list(report.get("held") or []),
        chi2_red=report.get("chi2_red"),
        joint_fit=report.get("joint_fit"),
        drift_ug_per_k={k: (drift.get(k) or {}).get("abs_slope_ug_per_k")
                        for k in ("before", "after")},
        steps=steps, bands=[_band_row(b) for b in report.get("bands") or []],
        notes=[str(n) for n in report.get("notes") or []],
    )


@router.get("/{calibration_id}/holdout", response_model=dict[str, Any])
async def calibration_holdout(calibration_id: DbIdPath, request: Request) -> dict[str, Any]:
    """The leave-one-position-out figures (``loo_rmse_ug``, ``dof``, ``warnings``) of
    ``soakcal calibrate``, from the fit redone on the stored measurements."""
    return (await refit_of(request, calibration_id)).holdout


def _step_row(st: dict[str, Any], soak: dict[str, Any]) -> StepRow:
    return StepRow(
        step=int(st.get("step", 0)), setpoint_c=st.get("setpoint_c", soak.get("setpoint_c")),
        temperature_c=st.get("temperature_c"), positions=st.get("positions"),
        rmse_before_ug=_ug(st.get("rmse_before_mg")),
        rmse_step_fit_ug=_ug(st.get("rmse_measurement_mg")),
        rmse_after_ug=_ug(st.get("rmse_polynomial_mg")),
        chi2_red=st.get("chi2_red"), soak_s=soak.get("soak_s"), soak_reason=soak.get("reason"))


def _band_row(b: dict[str, Any]) -> BandRow:
    lo_c, hi_c = b["band_c"]
    return BandRow(lo_c=lo_c, hi_c=hi_c, rows=b["rows"], positions=b["positions"],
                   rmse_before_ug=_ug(b.get("rmse_before_mg")),
                   rmse_after_ug=_ug(b.get("rmse_after_mg")), legs=b.get("legs"))


def _ug(mg: float | None) -> float | None:
    return None if mg is None or not math.isfinite(mg) else round(mg * 1e3, 1)


def _rms(values: list[float | None]) -> float | None:
    """Over steps, as the calibration's own rmse_ug (calibration.fitting.rmse_after_ug)."""
    finite = [v for v in values if v is not None]
    return round(math.sqrt(sum(v * v for v in finite) / len(finite)), 1) if finite else None
