"""Bench calibrations from campaigns, stored, and applied to later reports.

From a campaign's measurements: per set-point, the mean encoder read-back and the mean
measured pose (rotation from the stored raw quaternions) form one observation, with the
standard error of the mean as its 1-sigma (floored, so that a perfectly repeatable
set-point does not dominate). ``tofpose.calibration.bench.calibrate_bench`` fits the mount and
placement; the result is stored with its uncertainty and residuals. A report given a
calibration uses ``camera_target(encoders, mount, placement)`` per frame as its
reference ("calibrated").
"""

from __future__ import annotations

import numpy as np
from sqlalchemy import func, select
from sqlalchemy.orm import Session

from backend.db.models import CalibrationRow, MeasurementRow, SetPointRow
from backend.services.store import commit_unique
from tofpose.calibration.bench import BenchObservation, calibrate_bench, mean_pose
from tofpose.core.geometry import RigidTransform, facing_euler_deg, rotation_from_quaternion_wxyz
from tofpose.lab.kinematics import camera_target

SIGMA_FLOOR_MM = 0.02
SIGMA_FLOOR_DEG = 0.002


def observations(session: Session, campaign_id: int) -> list[BenchObservation]:
    """One observation per set-point with at least 2 ok frames that carry encoders."""
    q = (
        select(MeasurementRow, SetPointRow.index)
        .join(SetPointRow, MeasurementRow.setpoint_id == SetPointRow.id)
        .where(SetPointRow.campaign_id == campaign_id, MeasurementRow.ok.is_(True))
        .order_by(SetPointRow.index, MeasurementRow.id)
    )
    groups: dict[int, list[MeasurementRow]] = {}
    for m, index in session.execute(q).all():
        if m.encoders and m.qw is not None:
            groups.setdefault(index, []).append(m)
    out = []
    for rows in groups.values():
        if len(rows) < 2:
            continue
        poses = [
            RigidTransform(
                rotation_from_quaternion_wxyz([m.qw, m.qx, m.qy, m.qz]),
                np.array([m.x_mm, m.y_mm, m.z_mm]),
            )
            for m in rows
        ]
        mean = mean_pose(poses)
        n = len(rows)
        t_sd = np.std([p.t_mm for p in poses], axis=0, ddof=1)
        r_sd = np.std([facing_euler_deg(p.R) for p in poses], axis=0, ddof=1)
        readings = [m.encoders or {} for m in rows]  # every one has encoders (above)
        enc = {a: float(np.mean([r[a] for r in readings])) for a in readings[0]}
        out.append(
            BenchObservation(
                enc,
                mean,
                sigma_mm=max(float(np.sqrt(np.mean(t_sd**2)) / np.sqrt(n)), SIGMA_FLOOR_MM),
                sigma_deg=max(float(np.sqrt(np.mean(r_sd**2)) / np.sqrt(n)), SIGMA_FLOOR_DEG),
            )
        )
    return out


def calibrate_from_campaign(
    session: Session,
    campaign_id: int,
    name: str,
    nominal_mount: RigidTransform,
    nominal_placement: RigidTransform,
) -> CalibrationRow:
    """Fit and store; ``ValueError`` (too few or degenerate set-points), ``NameTakenError``."""
    obs = observations(session, campaign_id)
    cal = calibrate_bench(obs, nominal_mount, nominal_placement)
    row = CalibrationRow(
        name=name,
        campaign_id=campaign_id,
        mount=cal.T_inner_camera.as_matrix().tolist(),
        placement=cal.T_lab_target.as_matrix().tolist(),
        sigmas=[float(v) for v in cal.sigmas],
        residual_mm=[float(v) for v in cal.residual_mm],
        residual_deg=[float(v) for v in cal.residual_deg],
        chi2_per_dof=float(cal.chi2_per_dof),
        n_observations=len(obs),
    )
    session.add(row)
    commit_unique(session, f"a calibration named {name!r}")
    return row


def get_calibration(session: Session, calibration_id: int) -> CalibrationRow | None:
    return session.get(CalibrationRow, calibration_id)


def stored_calibrations(session: Session) -> list[CalibrationRow]:
    """Stored calibrations, newest first."""
    return list(session.scalars(select(CalibrationRow).order_by(CalibrationRow.id.desc())))


def count_calibrations(session: Session) -> int:
    return session.scalar(select(func.count()).select_from(CalibrationRow)) or 0


def transform(matrix: list[list[float]]) -> RigidTransform:
    M = np.asarray(matrix, float)
    return RigidTransform(M[:3, :3], M[:3, 3])


def calibrated_reference(row: CalibrationRow, encoders: dict[str, float]) -> dict[str, float]:
    """The reference pose of one frame under a calibration: x, y, z mm and facing Euler."""
    T = camera_target(encoders, transform(row.mount), transform(row.placement))
    p, y, r = (float(v) for v in facing_euler_deg(T.R))
    x, yy, z = (float(v) for v in T.t_mm)
    return {"x_mm": x, "y_mm": yy, "z_mm": z, "pitch_deg": p, "yaw_deg": y, "roll_deg": r}
