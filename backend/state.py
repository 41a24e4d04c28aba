"""What the running app owns, built by ``create_app``'s lifespan and reached by routes
through ``request.app.state.tofpose``."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

from sqlalchemy import Engine
from sqlalchemy.orm import Session, sessionmaker

from backend.drivers.factory import Devices
from backend.services.audit import AuditService
from backend.services.campaigns.campaigns import CampaignService
from backend.services.heavy_work import HeavyWork
from backend.services.jobs.reprocessing import ReprocessService
from backend.services.jobs.studies import StudyService
from backend.services.keys import KeyService
from backend.services.live.acquisition import AcquisitionService
from backend.services.live.hub import LiveHub
from backend.services.live.imaging import ImageRenderer
from backend.services.motion import MotionService
from backend.services.recordings import RecordingService
from backend.settings import Settings


@dataclass
class AppState:
    settings: Settings
    keys: KeyService  # API keys, verified in memory
    audit: AuditService  # the audit trail's writer thread and reads
    engine: Engine
    sessions: sessionmaker[Session]
    devices: Devices
    hub: LiveHub
    acquisition: AcquisitionService
    campaigns: CampaignService
    studies: StudyService
    reprocessings: ReprocessService
    motion: MotionService  # soft limits, ownership and health in front of devices.motion
    renderer: ImageRenderer = field(default_factory=ImageRenderer)
    heavy_work: HeavyWork = field(default_factory=HeavyWork)  # reports and exports, bounded
    recordings: RecordingService | None = None  # recordings on demand (the lifespan makes it)
    started_monotonic: float = field(default_factory=time.monotonic)
    scene: Any = None  # backend.services.live.scene.LiveScene when the 3-D scene runs
    scene_reason: str = ""  # why it does not run
    foxglove: Any = None  # backend.services.live.foxglove_live.LiveFoxglove when it runs
    foxglove_reason: str = ""  # why it does not run
    live_clients: dict[str, int] = field(default_factory=dict)  # /ws/live connections by address

    @property
    def uptime_s(self) -> float:
        return time.monotonic() - self.started_monotonic
