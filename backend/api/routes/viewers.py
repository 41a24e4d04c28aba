"""GET /api/viewers/foxglove-layout.json, GET /api/viewers/rerun-blueprint.rbl: the viewer
layouts for the MCAP downloads (docs/interop.md, "Viewer layouts"), as ``tofpose export
mcap`` writes them beside its file."""

from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Annotated

from fastapi import APIRouter, HTTPException, Query
from fastapi.responses import FileResponse, Response

from backend.api.contract import errors
from backend.api.deps import ReadAuth
from tofpose.io.interop.viewers import FOXGLOVE_LAYOUT

router = APIRouter(prefix="/api/viewers", tags=["recordings"])

McapFileQuery = Annotated[
    str,
    Query(
        pattern=r"^[A-Za-z0-9][A-Za-z0-9._-]{0,99}\.mcap$",
        description="the MCAP file the blueprint is for, named as it is opened "
        "(campaign-3.mcap): Rerun binds a blueprint to the file's name without .mcap",
        examples=["campaign-3.mcap"],
    ),
]


@router.get(
    "/foxglove-layout.json",
    dependencies=[ReadAuth],
    response_class=FileResponse,
    responses={200: {"content": {"application/json": {}}, "description": "the layout"}},
)
def get_foxglove_layout():
    """The Foxglove layout for our MCAP files (the app's layout menu, "Import from
    file..."): 3-D view in the camera frame with the target's trail, images with the
    overlay, plots of the pose and the turntable."""
    return FileResponse(
        FOXGLOVE_LAYOUT, media_type="application/json", filename="tofpose.foxglove-layout.json"
    )


@router.get(
    "/rerun-blueprint.rbl",
    dependencies=[ReadAuth],
    response_class=Response,
    responses={
        200: {"content": {"application/octet-stream": {}}, "description": "the blueprint"},
        **errors(503),
    },
)
def get_rerun_blueprint(file: McapFileQuery):
    """The Rerun blueprint for the MCAP file ``file`` (``rerun FILE.mcap FILE.rbl``): the
    3-D view in the camera frame with the target's trail and the images. 503 when the
    server has no rerun-sdk to build it."""
    from tofpose.io.interop.rerun_blueprint import mcap_application_id, save_blueprint

    stem = mcap_application_id(file)
    with tempfile.TemporaryDirectory() as d:
        out = Path(d) / "blueprint.rbl"
        try:
            save_blueprint(out, stem, series=False)
        except ImportError as exc:
            raise HTTPException(
                503,
                "this server has no rerun-sdk to build a Rerun blueprint (pip install "
                "rerun-sdk), or run `tofpose export mcap` where it is installed",
            ) from exc
        data = out.read_bytes()
    return Response(
        data,
        media_type="application/octet-stream",
        headers={"Content-Disposition": f'attachment; filename="{stem}.rbl"'},
    )
