"""The camera during a campaign: its settings applied per set-point, and the settings it
had before the campaign put back when the campaign ends, is paused, stopped or fails
(docs/campaigns.md, "Camera settings and metadata").

Settings are applied on the acquisition thread between two frames
(``AcquisitionService.submit``), and ``apply`` returns once the driver has them, so every
frame read after that was taken with them. The set-point collector counts only frames
captured after the move has settled, which is after the change; in addition it checks
each frame's reported integration time (``expected_integration_us``).
"""

from __future__ import annotations

import logging
from dataclasses import replace
from typing import Any

from backend.drivers.base import CameraSettings
from backend.services.live.acquisition import AcquisitionService

log = logging.getLogger(__name__)

APPLY_TIMEOUT_S = 10.0


class CampaignCamera:
    """Applies a campaign's camera settings and restores the camera's own afterwards.

    ``begin(base)``: remember the camera's settings now and apply the campaign-wide
    ``base`` (a ``CameraSettings`` field dict, or None). ``for_setpoint(setting)``: the
    set-point's ``integration_time_us`` / ``modulation_frequency_mhz`` over the base
    (an integration time turns auto exposure off); a set-point without settings gets the
    base again. ``restore()``: the remembered settings, once.
    """

    def __init__(self, acquisition: AcquisitionService, timeout_s: float = APPLY_TIMEOUT_S):
        self.acquisition = acquisition
        self.timeout_s = timeout_s
        self.previous: CameraSettings | None = None
        self.base: CameraSettings | None = None
        self.applied: CameraSettings | None = None

    def _apply(self, wanted: CameraSettings) -> CameraSettings:
        cam = self.acquisition.camera
        if self.applied == wanted:
            return self.applied
        applied = self.acquisition.submit(lambda: cam.apply_settings(wanted)).result(self.timeout_s)
        self.applied = applied
        return applied

    def begin(self, base: dict[str, Any] | None) -> None:
        """Remember the camera's settings and apply ``base`` over them (if any). Read on
        the acquisition thread, after any change a person's request queued there before
        (``PUT /api/camera/settings`` checks and applies there in one step), so that the
        restore puts back what that request set."""
        cam = self.acquisition.camera
        current = self.acquisition.submit(cam.get_settings).result(self.timeout_s)
        self.previous = current
        self.applied = current
        self.base = self._apply(replace(current, **base)) if base else current

    def for_setpoint(self, setting: dict[str, Any] | None) -> CameraSettings:
        """Apply the set-point's settings (over the base); returns what the camera uses."""
        if self.base is None:
            raise RuntimeError("begin() first")
        wanted = self.base
        if setting:
            wanted = replace(wanted, **setting)
            if "integration_time_us" in setting:
                wanted = replace(wanted, auto_exposure=False)
        return self._apply(wanted)

    @property
    def expected_integration_us(self) -> float | None:
        """The integration time every frame must report now; None under auto exposure."""
        s = self.applied
        if s is None or s.auto_exposure:
            return None
        return s.integration_time_us

    def restore(self) -> str | None:
        """Put back the settings the camera had before ``begin`` (when the campaign
        changed them); returns why that failed, or None."""
        previous, self.previous = self.previous, None
        if previous is None or self.applied == previous:
            return None
        try:
            self._apply(previous)
        except Exception as exc:
            log.warning("the camera's settings could not be restored: %s", exc)
            return f"the camera's previous settings could not be restored: {exc}"
        return None
