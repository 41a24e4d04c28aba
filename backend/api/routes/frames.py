"""GET /api/frames/latest/{kind}.png with optional detection overlay."""

from __future__ import annotations

import asyncio
from enum import StrEnum
from typing import Annotated

from fastapi import APIRouter, HTTPException, Query, Response

from backend.api.contract import errors
from backend.api.deps import ReadAuth, StateDep

router = APIRouter(prefix="/api/frames", tags=["frames"], dependencies=[ReadAuth])


class ImageKind(StrEnum):
    gray = "gray"
    distance = "distance"


@router.get(
    "/latest/{kind}.png",
    response_class=Response,
    responses={200: {"content": {"image/png": {}}}, **errors(404)},
)
async def get_latest_frame_png(
    kind: ImageKind,
    state: StateDep,
    overlay: Annotated[bool, Query(description="draw blobs, centroids and catalog ids")] = False,
    scale: Annotated[int, Query(ge=1, le=4, description="nearest-neighbour upscaling")] = 1,
) -> Response:
    sample = state.acquisition.latest
    if sample is None:
        raise HTTPException(404, "no frame has been captured yet")
    f = sample.frame
    # Rendered on the renderer's own thread (not the event loop, not the acquisition
    # thread), shared with identical requests, kept in a small LRU: see ImageRenderer.
    fut = state.renderer.png(
        f.index,
        kind.value,
        f.gray,
        f.distance_mm,
        sample.result,
        overlay=overlay,
        scale=scale,
        full_scale_counts=state.acquisition.camera.model.full_scale_counts,
    )
    index, png = await asyncio.wrap_future(fut)
    return Response(
        png,
        media_type="image/png",
        headers={"Cache-Control": "no-store", "X-Frame-Index": str(index)},
    )
