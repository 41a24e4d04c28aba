"""The rows of the CSV that ``tofpose estimate`` (and ``tofpose reprocess``) writes: one
per frame, the pose with its 1-sigma, and with ``--filter`` the relative-state filter's
rate and velocity. Formatting lives here once, so that a re-processed chunk's rows are
the serial command's byte for byte."""

from __future__ import annotations

import sys
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from tqdm import tqdm

from tofpose.lab.relative_state import STATE_COLUMNS, RelativeState
from tofpose.lab.smoothing import PoseOrNone, relative_states

CSV_COLUMNS = (
    "frame",
    "time_s",
    "ok",
    "n_matched",
    "x_mm",
    "y_mm",
    "z_mm",
    "qw",
    "qx",
    "qy",
    "qz",
    "pitch_deg",
    "yaw_deg",
    "roll_deg",
    "residual_mm",
    # appended later (readers of the columns above keep working): the pose's predicted
    # 1-sigma, position and rotation-vector components
    "sigma_x_mm",
    "sigma_y_mm",
    "sigma_z_mm",
    "sigma_rx_deg",
    "sigma_ry_deg",
    "sigma_rz_deg",
)

#: with ``estimate --filter``: the relative-state filter's state at each frame
#: (``tofpose.lab.relative_state``): angular rate in the camera frame, velocity, their 1-sigma,
#: and what the filter did with the frame's pose
FILTER_COLUMNS = STATE_COLUMNS


def pose_row(frame: int, time_s: float, r) -> list:
    """``CSV_COLUMNS`` of one frame's ``PoseResult`` (empty pose fields without a pose)."""
    row = [frame, f"{time_s:.6f}", int(r.ok), r.n_matched]
    if not r.ok:
        return row + [""] * 17
    row += [f"{v:.4f}" for v in r.t_mm]
    row += [f"{v:.8f}" for v in r.quaternion_wxyz]
    row += [f"{v:.5f}" for v in r.euler_deg]
    row += [f"{r.residual_mm:.4f}"]
    sd = np.sqrt(np.clip(np.diag(r.covariance), 0.0, None))
    row += [f"{v:.4f}" for v in sd[3:]]
    row += [f"{v:.5f}" for v in np.degrees(sd[:3])]
    return row


def state_cells(s: RelativeState | None) -> list:
    """``FILTER_COLUMNS`` of one frame's relative state (empty without one)."""
    if s is None:
        return [""] * len(FILTER_COLUMNS)
    return (
        [f"{v:.4f}" for v in s.angular_rate_deg_s]
        + [f"{v:.3f}" for v in s.velocity_mm_s]
        + [f"{v:.4f}" for v in s.angular_rate_sigma_deg_s]
        + [f"{v:.3f}" for v in s.velocity_sigma_mm_s]
        + [s.status]
    )


@dataclass
class HeldRows:
    """A recording's CSV rows held for the filter's pass over all its poses (``--filter``:
    the smoother needs the poses after each frame): ``add`` each frame's row, time and
    pose (R (3, 3), t_mm (3,), covariance (6, 6)) or None; ``write`` them with
    ``filter_rows``' columns appended."""

    rows: list[list] = field(default_factory=list)
    time_s: list[float] = field(default_factory=list)
    poses: list[PoseOrNone] = field(default_factory=list)

    def add(self, row: list, time_s: float, pose: PoseOrNone) -> None:
        self.rows.append(row)
        self.time_s.append(time_s)
        self.poses.append(pose)

    def write(self, writer, *, causal: bool = False, progress: bool = False) -> None:
        """Every held row plus its ``FILTER_COLUMNS`` through ``writer`` (a csv.writer)."""
        cells = filter_rows(self.time_s, self.poses, causal=causal, progress=progress)
        writer.writerows(row + c for row, c in zip(self.rows, cells, strict=True))


def result_pose(r) -> PoseOrNone:
    """(R, t_mm, covariance) of a ``PoseResult`` with a pose, else None."""
    if r.ok and r.R is not None and r.t_mm is not None and r.covariance is not None:
        return (r.R, r.t_mm, r.covariance)
    return None


def filter_rows(
    time_s: Sequence[float],
    poses: Sequence[PoseOrNone],
    *,
    causal: bool = False,
    progress: bool = False,
) -> list[list]:
    """``FILTER_COLUMNS`` of every frame of a recording (``tofpose.lab.smoothing
    .relative_states``: smoothed over all the poses, or ``causal`` the filter's state
    from the poses up to each frame); time_s (n,), poses n items of (R (3, 3), t_mm
    (3,), covariance (6, 6)) or None; ``progress``: a bar on stderr over the passes."""
    with tqdm(
        total=3 * len(time_s), desc="filter", unit="frame", disable=not progress, file=sys.stderr
    ) as bar:
        states = relative_states(time_s, poses, causal=causal, advance=bar.update)
    return [state_cells(s) for s in states]
