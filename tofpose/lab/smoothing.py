"""The relative state at every frame of a recording from all of its poses, before and
after the frame: a two-filter smoother over the motion-model filter
(``tofpose.lab.motion_models``), for ``tofpose estimate --filter`` and ``tofpose
reprocess --filter``, which hold the whole recording.

A causal filter (the live loop's) knows at frame k only the poses up to k: its rate
starts from nothing at the first pose, converges over seconds, and lags a rate that
changes. A recording has the poses after k too. The same filter is run twice, forward
over the poses in time order and backward over them in reverse (a motion run backward
is a motion of the same model, its rate and velocity negated; the filter is fed the
negated times, so they increase), and the two estimates of frame k are fused:

- forward ``f``: the forward filter after the poses up to and including k;
- backward ``b``: the backward filter after the poses from the last down to k + 1,
  predicted to frame k (it does not hold pose k, so no pose counts twice), its rate and
  velocity negated (``J = diag(I, I, -I, -I)`` on the (12,) error state);
- the smoothed state is the product of the two Gaussians in the forward state's error
  coordinates (rotation vector of ``R R_f^T`` rad, mm, rad/s, mm/s): with ``d`` the
  backward state's error against the forward one, ``K = P_f (P_f + J P_b J)^-1``,
  ``x = x_f (+) K d``, ``P = P_f - K P_f`` (Fraser and Potter's two-filter smoother,
  the error state on SO(3) x R^9 as in the filter).

At the first frames the backward filter has converged (it ends there) and at the last
the forward one has, so the rate holds from the first frame to the last and does not lag
a changing rate (both filters lag, in opposite directions). Where either filter has no
state the other's is reported; a forward filter that restarted (a gap, a reset) restarts
its own estimate and the fusion weighs it by its covariance. The status and innovation of
each row stay the forward filter's: what it did with that frame's pose.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace

import numpy as np

from tofpose.lab.motion_models import TwoModelRelativeState
from tofpose.lab.relative_state import RelativeState, _exp, _log

#: the backward filter's error state in the forward one's convention: rate and velocity
#: change sign when time runs backward
_REVERSE = np.diag([1.0] * 6 + [-1.0] * 6)


def reversed_state(state: RelativeState) -> RelativeState:
    """A backward filter's state (at negated time) as a forward one's: time, rate and
    velocity negated, the covariance's rate and velocity blocks' cross terms with the
    pose negated."""
    w = -state.angular_rate_deg_s
    return replace(
        state,
        time_s=-state.time_s,
        angular_rate_deg_s=w,
        angular_rate_target_deg_s=state.R.T @ w,
        velocity_mm_s=-state.velocity_mm_s,
        covariance=_REVERSE @ state.covariance @ _REVERSE,
    )


def fused(forward: RelativeState, backward: RelativeState) -> RelativeState:
    """The product of the forward state and a backward state of the same frame (both in
    the forward convention: ``reversed_state``), in the forward state's error
    coordinates (module docstring); status and innovation the forward state's."""
    d = np.concatenate(
        [
            _log(backward.R @ forward.R.T),
            backward.t_mm - forward.t_mm,
            np.radians(backward.angular_rate_deg_s - forward.angular_rate_deg_s),
            backward.velocity_mm_s - forward.velocity_mm_s,
        ]
    )
    P_f = forward.covariance
    K = np.linalg.solve(P_f + backward.covariance, P_f).T  # P_f (P_f + P_b)^-1, symmetric P
    dx = K @ d
    P = P_f - K @ P_f
    R = _exp(dx[0:3]) @ forward.R
    w = forward.angular_rate_deg_s + np.degrees(dx[6:9])
    return replace(
        forward,
        R=R,
        t_mm=forward.t_mm + dx[3:6],
        angular_rate_deg_s=w,
        angular_rate_target_deg_s=R.T @ w,
        velocity_mm_s=forward.velocity_mm_s + dx[9:12],
        covariance=0.5 * (P + P.T),
    )


PoseOrNone = tuple[np.ndarray, np.ndarray, np.ndarray] | None


def smoothed_states(
    time_s: Sequence[float],
    poses: Sequence[PoseOrNone],
    make_filter: Callable[[], TwoModelRelativeState] = TwoModelRelativeState,
) -> list[RelativeState | None]:
    """The smoothed state at each frame (module docstring).

    time_s : (n,) frame times, non-decreasing; poses : n items, each (R (3, 3), t_mm (3,),
    covariance (6, 6)) of the frame's pose or None; ``make_filter`` : a new filter with
    ``step`` and ``state_at`` (``TwoModelRelativeState``). Returns n states (None where
    neither filter has one: a recording without poses)."""
    n = len(time_s)
    if len(poses) != n:
        raise ValueError(f"{n} frame times but {len(poses)} poses")
    times = [float(t) for t in time_s]
    if any(b < a for a, b in zip(times, times[1:], strict=False)):
        raise ValueError("frame times must not decrease for the smoother")
    forward = make_filter()
    fwd = [
        forward.step(t, *(p if p is not None else (None, None, None)))
        for t, p in zip(times, poses, strict=True)
    ]
    backward = make_filter()
    bwd: list[RelativeState | None] = [None] * n
    for k in range(n - 1, -1, -1):
        if backward.initialised:
            bwd[k] = reversed_state(backward.state_at(-times[k]))
        p = poses[k]
        if p is not None:
            backward.step(-times[k], *p)
    out: list[RelativeState | None] = []
    for f, b in zip(fwd, bwd, strict=True):
        if f is None or b is None:
            out.append(f if b is None else replace(b, status="predicted"))
        else:
            out.append(fused(f, b))
    return out


def causal_states(
    time_s: Sequence[float],
    poses: Sequence[PoseOrNone],
    make_filter: Callable[[], TwoModelRelativeState] = TwoModelRelativeState,
) -> list[RelativeState | None]:
    """The filter's state at each frame from the poses up to it (the live loop's view):
    time_s (n,), poses as ``smoothed_states``; None before the first pose."""
    filt = make_filter()
    return [
        filt.step(float(t), *(p if p is not None else (None, None, None)))
        for t, p in zip(time_s, poses, strict=True)
    ]


def relative_states(
    time_s: Sequence[float], poses: Sequence[PoseOrNone], causal: bool = False
) -> list[RelativeState | None]:
    """``smoothed_states`` (all the poses), or with ``causal`` ``causal_states`` (the
    poses up to each frame), with the motion-model filter of ``tofpose estimate
    --filter``."""
    return causal_states(time_s, poses) if causal else smoothed_states(time_s, poses)
