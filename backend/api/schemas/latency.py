"""GET /api/live/stats and the per-frame latency of /ws/live (docs/server.md, "Latency
and dropped frames")."""

from __future__ import annotations

from pydantic import BaseModel, Field


class LatencySummaryPublic(BaseModel):
    """Median and 95th percentile of one latency over the window (None: no frame)."""

    median_ms: float | None
    p95_ms: float | None
    n: int = Field(description="latencies in the window")


class DroppedFramesPublic(BaseModel):
    """Frames lost, by where."""

    camera: int | None = Field(
        description="gaps in the camera's own frame counter (None: it has none)"
    )
    pipeline: int = Field(
        description="frames the camera's rate offered while the pipeline was busy"
    )
    clients: int = Field(
        description="frames live WebSocket clients' mailboxes dropped (slow readers)"
    )


class ClockAnchorPublic(BaseModel):
    """One moment on both clocks: a stamp's UTC ns is wall_ns + (stamp - monotonic_ns)."""

    monotonic_ns: int
    wall_ns: int


class LiveClientPublic(BaseModel):
    """One live WebSocket client: frames offered to it and dropped from its mailbox."""

    address: str
    offered: int
    dropped: int


class LiveStatsPublic(BaseModel):
    """Latency and frame accounting of the live stream, over a sliding window.

    Stamps are host monotonic ns: capture (``capture_source`` says what it is on this
    camera), arrival at the server, pose ready, WebSocket sent (per client)."""

    window_s: float
    frames_in_window: int
    frames_total: int = Field(description="frames through the pipeline since the start")
    capture_source: str
    capture_to_arrival: LatencySummaryPublic
    capture_to_pose: LatencySummaryPublic
    capture_to_sent: LatencySummaryPublic
    dropped_in_window: DroppedFramesPublic
    dropped_total: DroppedFramesPublic = Field(description="since the server started")
    clock: ClockAnchorPublic
    clients: list[LiveClientPublic]


class FrameStampsPublic(BaseModel):
    """One frame's stamps (host monotonic ns) in its /ws/live pose message."""

    capture_ns: int
    arrival_ns: int
    pose_ready_ns: int
    capture_from_device: bool
    capture_to_pose_ms: float


class FrameLatencyPublic(BaseModel):
    """The statistics every /ws/live pose message carries (``latency``)."""

    capture_to_pose: LatencySummaryPublic
    capture_to_sent: LatencySummaryPublic
    dropped_total: DroppedFramesPublic
    window_s: float
