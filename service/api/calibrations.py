"""Calibrations as ops query them: per sensor, one document, coefficients at a temperature."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from fastapi import APIRouter, Depends, HTTPException, Query, Request, Response
from fastapi.responses import PlainTextResponse
from sqlalchemy import select
from sqlalchemy.orm import Session, sessionmaker
from starlette.concurrency import run_in_threadpool

from calibration.errors import CalibrationError, OutOfRange
from service.api import auth, coefficients
from service.api.deps import DbIdPath, SerialPath, SessionDep
from service.api.schemas import CalibrationSummary, CoefficientsOut
from service.db.models import Calibration
from service.db.timestamps import as_utc

router = APIRouter(prefix="/api/v1", tags=["calibrations"], dependencies=[Depends(auth.viewer)])

_NEWEST_FIRST = (Calibration.created_at.desc(), Calibration.id.desc())


@router.get("/sensors/{serial}/calibrations", response_model=list[CalibrationSummary])
def sensor_calibrations(serial: SerialPath, session: SessionDep) -> list[Any]:
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
def calibration_document(calibration_id: DbIdPath, session: SessionDep) -> dict[str, Any]:
    """The full model document, as ``soakcal calibrate -o`` writes it."""
    row = session.get(Calibration, calibration_id)
    if row is None:
        raise HTTPException(status_code=404, detail=f"calibration {calibration_id} not found")
    return row.model


@router.get(
    "/calibrations/{calibration_id}/export",
    response_class=PlainTextResponse,
    responses={
        200: {"description": "the firmware export: a C99 header (format=c) or flat JSON",
              "content": {"text/x-c": {}, "application/json": {}}},
        404: {"description": "no such calibration"},
        422: {"description": "the model cannot be exported (e.g. it carries extension terms)"},
    },
)
def calibration_export(
    calibration_id: DbIdPath,
    session: SessionDep,
    format: Annotated[Literal["c", "json-flat"], Query(description="c or json-flat")] = "c",
) -> Response:
    """``soakcal export`` of this calibration, as a download (docs/model-file.md)."""
    from calibration.export import export_text
    from calibration.model_file import load_conditioning_dict, load_model_dict

    row = session.get(Calibration, calibration_id)
    if row is None:
        raise HTTPException(status_code=404, detail=f"calibration {calibration_id} not found")
    name = f"calibration-{calibration_id}"
    try:
        text = export_text(load_model_dict(row.model), format, source_name=f"{name}.json",
                           conditioning=load_conditioning_dict(row.model))
    except CalibrationError as exc:
        raise HTTPException(status_code=422, detail=str(exc)) from None
    media, ext = ("text/x-c", "h") if format == "c" else ("application/json", "json")
    return Response(text, media_type=media, headers={
        "Content-Disposition": f'attachment; filename="soakcal-{name}.{ext}"'})


@router.get(
    "/sensors/{serial}/coefficients",
    response_model=CoefficientsOut,
    responses={
        404: {"description": "the sensor has no calibration"},
        422: {"description": "temperature outside valid_c without extrapolate=true"},
    },
)
async def sensor_coefficients(
    serial: SerialPath,
    request: Request,
    temperature_c: Annotated[float, Query(description="°C", allow_inf_nan=False)],
    extrapolate: bool = False,
) -> CoefficientsOut:
    """The latest calibration at ``temperature_c``: calibrated = matrix · (raw − bias_g)."""
    # The hot query path: all blocking work in ONE thread-pool hop (a sync handler with a
    # session dependency costs several), holding a database connection only for the
    # queries and needing no second thread while it does (so it cannot take part in the
    # deadlock service/api/deps.py describes).
    return await run_in_threadpool(
        _coefficients,
        request.app.state.session_factory,
        _model_cache(request),
        serial,
        temperature_c,
        extrapolate,
    )


def _coefficients(
    factory: sessionmaker[Session],
    cache: coefficients.ModelCache,
    serial: str,
    temperature_c: float,
    extrapolate: bool,
) -> CoefficientsOut:
    doc: dict[str, Any] | None = None
    with factory() as session:
        latest = session.execute(
            select(Calibration.id, Calibration.valid_lo_c, Calibration.valid_hi_c)
            .where(Calibration.sensor == serial)
            .order_by(*_NEWEST_FIRST)
            .limit(1)
        ).first()
        if latest is None:
            raise HTTPException(status_code=404, detail=f"sensor {serial!r} has no calibration")
        calibration_id, valid_lo_c, valid_hi_c = latest
        model = cache.get(calibration_id)
        if model is None:
            doc = session.scalar(select(Calibration.model).where(Calibration.id == calibration_id))
    outside = not valid_lo_c <= temperature_c <= valid_hi_c
    if outside and not extrapolate:
        raise _out_of_range(temperature_c, calibration_id, valid_lo_c, valid_hi_c)
    try:
        if model is None:
            model = coefficients.load_model(doc)  # type: ignore[arg-type]
            cache.put(calibration_id, model)
        matrix, bias_g = coefficients.evaluate(model, temperature_c, extrapolate)
    except OutOfRange as exc:
        msg = str(exc)
        raise _out_of_range(temperature_c, calibration_id, valid_lo_c, valid_hi_c, msg) from exc
    except coefficients.ModelUnavailable as exc:
        raise HTTPException(status_code=503, detail=str(exc)) from exc
    except CalibrationError as exc:  # a bad stored document: our fault, not the caller's
        raise HTTPException(
            status_code=500,
            detail=f"calibration {calibration_id}'s stored model is unusable: {exc}",
        ) from exc
    return CoefficientsOut(
        calibration_id=calibration_id,
        temperature_c=temperature_c,
        matrix=matrix,
        bias_g=bias_g,
        extrapolated=outside,
    )


def _model_cache(request: Request) -> coefficients.ModelCache:
    """The app's cache of loaded models (created on first use; the event loop is one thread)."""
    cache = getattr(request.app.state, "model_cache", None)
    if cache is None:
        cache = request.app.state.model_cache = coefficients.ModelCache()
    return cache


def _out_of_range(
    temperature_c: float,
    calibration_id: int,
    valid_lo_c: float,
    valid_hi_c: float,
    msg: str | None = None,
) -> HTTPException:
    msg = msg or (
        f"temperature {temperature_c} °C is outside calibration {calibration_id}'s valid range "
        f"[{valid_lo_c}, {valid_hi_c}] °C; pass extrapolate=true to use it anyway"
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
