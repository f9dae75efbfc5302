"""A calibration's report figures as PNG, drawn from its campaign's stored measurements.

The figures are those of ``soakcal calibrate --report-dir``
(``calibration.report.write_figures``: |g| error before/after per reading,
the SFEM parameters against temperature with their polynomials -- the seed
paper's Eq. 1 and Eq. 8, its Fig. 10 -- and the drift at fixed orientation,
its Fig. 11). The calibration row keeps the model, not the fit's per-reading
residuals, so the fit is redone from the stored measurements (the same
``calibrate_columns`` the engine ran, so the same numbers) the first time a
calibration's figures are asked for; the PNGs are then kept in memory.
"""

from __future__ import annotations

import re
import tempfile
import threading
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any

from fastapi import APIRouter, Depends, HTTPException, Request
from fastapi import Path as PathParam
from fastapi.responses import Response
from sqlalchemy.orm import Session, sessionmaker
from starlette.concurrency import run_in_threadpool

from service.api import auth
from service.db.models import Calibration

CACHE_CALIBRATIONS = 8
# Fits with no steps: ``soakcal calibrate`` draws no figures and gives no held-out figure.
STEPLESS = ("continuous", "warmup")
_NAME = re.compile(r"^[a-z_]{1,64}$")

router = APIRouter(
    prefix="/web/calibrations",
    tags=["dashboard"],
    dependencies=[Depends(auth.viewer)],
    responses={
        401: {"description": "missing, unknown, revoked or expired token"},
        404: {"description": "no such calibration, or no stored measurements to draw from"},
    },
)

CalibrationId = Annotated[int, PathParam(ge=1, le=2**31 - 1)]


@dataclass(frozen=True)
class Refit:
    """What the redone fit gives that the calibration row does not keep."""

    pngs: dict[str, bytes]
    holdout: dict[str, Any]  # calibration.holdout.leave_one_out: loo_rmse_ug, dof, warnings


class FigureCache:
    """The refit's figures and held-out figures per calibration, least recently used dropped;
    one fit at a time."""

    def __init__(self, max_entries: int = CACHE_CALIBRATIONS) -> None:
        self._entries: OrderedDict[int, Refit] = OrderedDict()
        self._max = max_entries
        self._lock = threading.Lock()

    def refit(self, factory: sessionmaker[Session], calibration_id: int) -> Refit:
        with self._lock:  # matplotlib is not thread-safe, and a fit costs seconds: do one
            if calibration_id in self._entries:
                self._entries.move_to_end(calibration_id)
                return self._entries[calibration_id]
            done = redo_fit(factory, calibration_id)
            self._entries[calibration_id] = done
            while len(self._entries) > self._max:
                self._entries.popitem(last=False)
            return done

    def figures(self, factory: sessionmaker[Session], calibration_id: int) -> dict[str, bytes]:
        return self.refit(factory, calibration_id).pngs


def redo_fit(factory: sessionmaker[Session], calibration_id: int) -> Refit:
    """Refit the calibration's campaign: its figures (``{name: png bytes}``) and the
    leave-one-position-out figures of ``soakcal calibrate`` (calibration/holdout.py)."""
    from calibration.recording import Recording
    from calibration.report import write_figures
    from service.engine import store
    from service.engine.calibrate import calibrate_columns

    with factory() as session:
        row = session.get(Calibration, calibration_id)
        if row is None:
            raise LookupError(f"calibration {calibration_id} not found")
        campaign_id = row.campaign_id
        method, rmse_ug = (row.report or {}).get("method"), row.rmse_ug
    if method in STEPLESS:
        # as `soakcal calibrate`: figures and leave-one-position-out are per step
        return Refit(pngs={}, holdout={
            "loo_rmse_ug": None, "rmse_ug": rmse_ug, "dof": None,
            "warnings": [f"leave one position out is given for step fits; a {method} fit has "
                         f"no steps (its per-band table is its report)"]})
    if campaign_id is None:
        raise LookupError(f"calibration {calibration_id} has no campaign: no stored recording")
    columns = store.measurement_columns(factory, campaign_id)
    if not columns["t_s"]:
        raise LookupError(f"campaign {campaign_id} has no stored measurements")
    values = calibrate_columns(columns, {"recording": f"campaign-{campaign_id}.csv"})
    import numpy as np

    recording = Recording.from_columns(
        {k: np.asarray(v, float) for k, v in columns.items()}, path=f"campaign-{campaign_id}.csv"
    )
    from calibration.holdout import leave_one_out

    with tempfile.TemporaryDirectory(prefix="soakcal-figures-") as tmp:
        paths = write_figures(values.fit, recording, tmp)
        pngs = {Path(p).stem: Path(p).read_bytes() for p in paths}
    return Refit(pngs=pngs, holdout=leave_one_out(recording, values.fit))


def _cache(request: Request) -> FigureCache:
    cache = getattr(request.app.state, "figure_cache", None)
    if cache is None:
        cache = request.app.state.figure_cache = FigureCache()
    return cache


async def refit_of(request: Request, calibration_id: int) -> Refit:
    """The calibration's refit (redone on first request, a few seconds), 404 when impossible."""
    try:
        return await run_in_threadpool(
            _cache(request).refit, request.app.state.session_factory, calibration_id
        )
    except LookupError as exc:
        raise HTTPException(status_code=404, detail=str(exc)) from exc


async def _figures(request: Request, calibration_id: int) -> dict[str, bytes]:
    return (await refit_of(request, calibration_id)).pngs


@router.get("/{calibration_id}/figures", response_model=list[str])
async def figure_names(calibration_id: CalibrationId, request: Request) -> list[str]:
    """The figure names of the calibration (drawn on first request: a few seconds)."""
    return sorted(await _figures(request, calibration_id))


@router.get(
    "/{calibration_id}/figures/{name}.png",
    response_class=Response,
    responses={200: {"content": {"image/png": {}}}, 404: {"description": "no such figure"}},
)
async def figure_png(calibration_id: CalibrationId, name: str, request: Request) -> Response:
    if not _NAME.match(name):
        raise HTTPException(status_code=404, detail="no such figure")
    pngs = await _figures(request, calibration_id)
    if name not in pngs:
        raise HTTPException(status_code=404, detail=f"no figure {name!r}; have {sorted(pngs)}")
    return Response(pngs[name], media_type="image/png", headers={"Cache-Control": "private"})
