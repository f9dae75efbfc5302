"""Calibrations as ops query them: per sensor, one document, coefficients at a temperature."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Depends, HTTPException, Query
from sqlalchemy import select

from calibration.errors import CalibrationError, OutOfRange
from service.api import auth, coefficients
from service.api.deps import SessionDep
from service.api.schemas import CalibrationSummary, CoefficientsOut
from service.db.models import Calibration
from service.db.timestamps import as_utc

router = APIRouter(prefix="/api/v1", tags=["calibrations"], dependencies=[Depends(auth.viewer)])

_NEWEST_FIRST = (Calibration.created_at.desc(), Calibration.id.desc())


@router.get("/sensors/{serial}/calibrations", response_model=list[CalibrationSummary])
def sensor_calibrations(serial: str, session: SessionDep) -> list[Any]:
    """Every calibration of the sensor, newest first (empty for an unknown serial)."""
    rows = session.scalars(
        select(Calibration).where(Calibration.sensor == serial).order_by(*_NEWEST_FIRST)
    )
    return [_summary(c) for c in rows]


@router.get(
    "/calibrations/{calibration_id}",
    response_model=dict[str, Any],
    responses={404: {"description": "no such calibration"}},
)
def calibration_document(calibration_id: int, session: SessionDep) -> dict[str, Any]:
    """The full model document, as ``soakcal calibrate -o`` writes it."""
    row = session.get(Calibration, calibration_id)
    if row is None:
        raise HTTPException(status_code=404, detail=f"calibration {calibration_id} not found")
    return row.model


@router.get(
    "/sensors/{serial}/coefficients",
    response_model=CoefficientsOut,
    responses={
        404: {"description": "the sensor has no calibration"},
        422: {"description": "temperature outside valid_c without extrapolate=true"},
    },
)
def sensor_coefficients(
    serial: str,
    session: SessionDep,
    temperature_c: Annotated[float, Query(description="°C", allow_inf_nan=False)],
    extrapolate: bool = False,
) -> CoefficientsOut:
    """The latest calibration at ``temperature_c``: calibrated = matrix · (raw − bias_g)."""
    row = session.scalars(
        select(Calibration).where(Calibration.sensor == serial).order_by(*_NEWEST_FIRST).limit(1)
    ).first()
    if row is None:
        raise HTTPException(status_code=404, detail=f"sensor {serial!r} has no calibration")
    outside = not row.valid_lo_c <= temperature_c <= row.valid_hi_c
    if outside and not extrapolate:
        raise _out_of_range(temperature_c, row)
    try:
        matrix, bias_g = coefficients.evaluate_model(row.model, temperature_c, extrapolate)
    except OutOfRange as exc:
        raise _out_of_range(temperature_c, row, str(exc)) from exc
    except coefficients.ModelUnavailable as exc:
        raise HTTPException(status_code=503, detail=str(exc)) from exc
    except CalibrationError as exc:  # a bad stored document: our fault, not the caller's
        raise HTTPException(
            status_code=500, detail=f"calibration {row.id}'s stored model is unusable: {exc}"
        ) from exc
    return CoefficientsOut(
        calibration_id=row.id,
        temperature_c=temperature_c,
        matrix=matrix,
        bias_g=bias_g,
        extrapolated=outside,
    )


def _out_of_range(temperature_c: float, row: Calibration, msg: str | None = None) -> HTTPException:
    msg = msg or (
        f"temperature {temperature_c} °C is outside calibration {row.id}'s valid range "
        f"[{row.valid_lo_c}, {row.valid_hi_c}] °C; pass extrapolate=true to use it anyway"
    )
    detail = [
        {
            "type": "value_error",
            "loc": ["query", "temperature_c"],
            "msg": msg,
            "input": temperature_c,
        }
    ]
    return HTTPException(status_code=422, detail=detail)


def _summary(row: Calibration) -> CalibrationSummary:
    return CalibrationSummary(
        id=row.id,
        sensor=row.sensor,
        campaign_id=row.campaign_id,
        created_at=as_utc(row.created_at),  # type: ignore[arg-type]
        valid_c=(row.valid_lo_c, row.valid_hi_c),
        rmse_ug=row.rmse_ug,
        model_version=row.model_version,
    )
