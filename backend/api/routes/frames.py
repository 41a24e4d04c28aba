"""GET /api/frames/latest/{kind}.png with optional detection overlay."""

from __future__ import annotations

from enum import StrEnum
from typing import Annotated

from fastapi import APIRouter, HTTPException, Query, Response

from backend.api.deps import ReadAuth, StateDep
from backend.services.imaging import render_png

router = APIRouter(prefix="/api/frames", tags=["frames"], dependencies=[ReadAuth])


class ImageKind(StrEnum):
    gray = "gray"
    distance = "distance"


@router.get(
    "/latest/{kind}.png",
    response_class=Response,
    responses={200: {"content": {"image/png": {}}}, 404: {"description": "no frame yet"}},
)
def latest_png(
    kind: ImageKind,
    state: StateDep,
    overlay: Annotated[bool, Query(description="draw blobs, centroids and catalog ids")] = False,
    scale: Annotated[int, Query(ge=1, le=4, description="nearest-neighbour upscaling")] = 1,
) -> Response:
    sample = state.acquisition.latest
    if sample is None:
        raise HTTPException(404, "no frame has been captured yet")
    f = sample.frame
    png = sample.cached(
        f"png:{kind.value}:{int(overlay)}:{scale}",
        lambda: render_png(kind.value, f.gray, f.distance_mm, sample.result,
                           overlay=overlay, scale=scale),
    )  # fmt: skip
    return Response(
        png,
        media_type="image/png",
        headers={"Cache-Control": "no-store", "X-Frame-Index": str(f.index)},
    )
