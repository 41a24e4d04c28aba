"""What several resources' schemas share: the strict request body, JSON integers and row
ids, a device's and the live pipeline's state."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import BaseModel, BeforeValidator, ConfigDict, Field


class StrictBody(BaseModel):
    """Request bodies: unknown fields, NaN/inf and values of the wrong JSON type are errors,
    not silently coerced (``true`` is not 1 deg, ``"5"`` is not a number, ``"yes"`` is not
    a boolean). Integers are accepted where a number is expected."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, strict=True)


def _integral_float_to_int(value: object) -> object:
    """JSON Schema's ``integer`` includes ``5.0``: take it as 5 (``5.5``, ``"5"`` and
    ``true`` stay errors under strict validation)."""
    if isinstance(value, float) and value.is_integer():
        return int(value)
    return value


JsonInt = Annotated[int, BeforeValidator(_integral_float_to_int)]
"""An integer as JSON Schema means it (strict otherwise)."""
RowId = Annotated[int, Field(ge=1, le=2**31 - 1), BeforeValidator(_integral_float_to_int)]
"""A stored row's id (constraints before the validator: pydantic writes them into the
schema as minimum/maximum only in this order)."""


class DeviceStatePublic(BaseModel):
    driver: str
    state: Literal["starting", "ok", "degraded", "stopped", "absent"]
    last_error: str | None = None
    error_count: int = 0
    model: str | None = Field(default=None, description="device model as the device reports it")
    firmware: str | None = Field(default=None, description="firmware or software version")
    link: Literal["up", "down"] | None = Field(
        default=None, description="connection to the device (real devices and their emulators)"
    )
    address: str | None = Field(default=None, description="where the device is reached")


class PipelineStatePublic(BaseModel):
    """The live pipeline's compiled kernels: compiled in the background at server start
    (about 1-2 min after an install, seconds from numba's cache); meanwhile the poses come
    from the pipeline's reference implementation (NumPy/SciPy, the same poses to ~0.01
    mm), then from the compiled one."""

    state: Literal["compiling", "ready", "failed"] = Field(
        description="the kernels' warm-up: compiling, ready, or failed (the poses then "
        "stay with the reference implementation)"
    )
    implementation: Literal["reference", "compiled"] | None = Field(
        description="which implementation of the pipeline measures the live frames: "
        "'reference' while the kernels compile, 'compiled' once they are ready; null in "
        "the warm-up's first second, when frames stream without a pose"
    )
    seconds: float = Field(description="since the warm-up started, or how long it took")
    detail: str = ""
