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
state the other's is reported. The backward filter runs once per segment the forward one
follows as one motion (``segments``: a new one where the time goes back or the forward
filter restarts after a gap or a reset), so a jump of the target is not smoothed across;
the poses the forward filter rejected are left out of the backward pass too (a glitch,
or the first poses after a jump it then resets on), and a frame's two estimates are
fused only where both filters took its pose (one that rejected it, or restarted on it,
is on the other side of a jump from the other) and their poses agree within
chi^2_6 at 1 - 1e-9 (``FUSION_GATE_CHI2``); else the estimate the frame's own pose lies
nearer to is reported (``supported``: after a jump, the backward one at the poses the
forward filter rejects while its prediction runs away), the forward one without a pose.
The status and innovation of each row stay the forward filter's: what it did with that
frame's pose. The cost: three propagations of both models a frame (forward, the backward
prediction, the backward step), about three times the causal filter's time, and the
poses held until the last frame.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace

import numpy as np
from scipy.spatial.transform import Rotation
from scipy.stats import chi2

from tofpose.lab.motion_models import TwoModelRelativeState
from tofpose.lab.relative_state import RelativeState

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


def _difference(forward: RelativeState, backward: RelativeState) -> np.ndarray:
    """(12,) the backward state's error against the forward one: rotation vector of
    R_b R_f^T (rad), mm, rad/s, mm/s."""
    return np.concatenate(
        [
            Rotation.from_matrix(backward.R @ forward.R.T).as_rotvec(),
            backward.t_mm - forward.t_mm,
            np.radians(backward.angular_rate_deg_s - forward.angular_rate_deg_s),
            backward.velocity_mm_s - forward.velocity_mm_s,
        ]
    )


def fused(
    forward: RelativeState, backward: RelativeState, difference: np.ndarray | None = None
) -> RelativeState:
    """The product of the forward state and a backward state of the same frame (both in
    the forward convention: ``reversed_state``), in the forward state's error
    coordinates (module docstring); status and innovation the forward state's.
    ``difference``: their (12,) ``_difference`` when already computed."""
    d = _difference(forward, backward) if difference is None else difference
    P_f = forward.covariance
    K = np.linalg.solve(P_f + backward.covariance, P_f).T  # P_f (P_f + P_b)^-1, symmetric P
    dx = K @ d
    P = P_f - K @ P_f
    R = Rotation.from_rotvec(dx[0:3]).as_matrix() @ forward.R
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

#: a frame's two estimates are fused only where both filters took its pose (or it had
#: none): a filter that rejected the pose is on the other side of a jump of the target
#: from the other one (or, the forward one, running away from it), and the product of
#: the two would match neither; the backward pass leaves out the poses the forward
#: filter rejected. The backward filter's statuses that took it ("reset": it restarted on it,
#: from the other side of a jump it had followed up to there, and is left out).
FUSED_STATUSES = ("updated", "predicted", "initialised")
#: ... and only where the two estimates of the pose (attitude and position: the first
#: six components) are within this squared Mahalanobis distance of each other under
#: P_f + P_b: chi^2_6 at 1 - 1e-9 (53.3). Two consistent filters' estimates are
#: independent and differ by chi^2_6; on the turntable's sine the two filters lag on
#: either side of the truth in the rate (the full 12-state distance reaches ~190 in 16 %
#: of frames, where their fusion is right) but agree on the pose (99 % of frames below
#: ~47, the worst ~54: that frame is not fused); after a 30 mm jump of the target the pose
#: parts differ by ~200. A frame not fused reports the estimate its own pose supports
#: (``supported``).
FUSION_GATE_CHI2 = float(chi2.isf(1e-9, 6))


def segments(time_s: Sequence[float], forward: Sequence[RelativeState | None]) -> list[range]:
    """The frames [a, b) the forward filter follows as one motion: a new segment where
    the time goes back (a replayed recording, a clock reset) or where the forward
    filter restarts once the segment has had a pose (``initialised``: after a gap;
    ``reset``: a motion it rejected and then took up). Each is smoothed on its own."""
    n = len(time_s)
    starts, posed = [0], False  # posed: the current segment has had a pose
    for k in range(n):
        f = forward[k]
        restart = f is not None and f.status in ("initialised", "reset")
        if k > 0 and (time_s[k] < time_s[k - 1] or (restart and posed)):
            starts.append(k)
            posed = False
        posed = posed or f is not None
    return [range(a, b) for a, b in zip(starts, [*starts[1:], n], strict=True)]


def smoothed_states(
    time_s: Sequence[float],
    poses: Sequence[PoseOrNone],
    make_filter: Callable[[], TwoModelRelativeState] = TwoModelRelativeState,
    *,
    advance: Callable[[int], None] | None = None,
) -> list[RelativeState | None]:
    """The smoothed state at each frame (module docstring).

    time_s : (n,) frame times; poses : n items, each (R (3, 3), t_mm (3,), covariance
    (6, 6)) of the frame's pose or None; ``make_filter`` : a new filter with ``step`` and
    ``state_at`` (``TwoModelRelativeState``); ``advance(frames)`` : called as the three
    passes (forward, backward, fusion) get through frames (3 n in all). Returns n states
    (None where neither filter has one: a recording without poses). The backward pass
    runs per ``segments`` (a time that goes back, a restart of the forward filter); two
    estimates are fused where the backward filter took the frame's pose and their poses
    agree (``agree``), else the one the frame's pose supports is reported
    (``supported``)."""
    n = len(time_s)
    if len(poses) != n:
        raise ValueError(f"{n} frame times but {len(poses)} poses")
    times = [float(t) for t in time_s]
    tick = advance or (lambda _frames: None)
    fwd = causal_states(times, poses, make_filter)
    tick(n)
    bwd: list[RelativeState | None] = [None] * n
    took = [True] * n  # whether the backward filter took frame k's pose
    for seg in segments(times, fwd):
        backward = make_filter()
        for k in reversed(seg):
            if backward.initialised:
                bwd[k] = reversed_state(backward.state_at(-times[k]))
            p = poses[k]
            f = fwd[k]
            if p is not None and (f is None or f.status != "rejected"):
                # a pose the forward filter rejected is not this segment's motion (a
                # glitch, or the first poses after a jump it then resets on): the
                # backward filter leaves it out too
                state = backward.step(-times[k], *p)
                took[k] = state is not None and state.status in FUSED_STATUSES
        tick(len(seg))
    out: list[RelativeState | None] = []
    for f, b, ok, p in zip(fwd, bwd, took, poses, strict=True):
        if f is None or b is None:
            out.append(
                f
                if b is None
                else replace(b, status="predicted", innovation_d2=float("nan"), n_rejected=0)
            )
            continue
        d = _difference(f, b)  # once, for the gate and the fusion
        if ok and f.status != "rejected" and agree(f, b, d):
            out.append(fused(f, b, d))
        else:
            out.append(supported(f, b, p))
    tick(n)
    return out


def supported(forward: RelativeState, backward: RelativeState, pose: PoseOrNone) -> RelativeState:
    """Of a frame's two estimates that are not fused, the one its own pose (R, t_mm,
    covariance) lies nearer to, in squared Mahalanobis distance under the pose's and the
    estimate's covariances: after a jump of the target the forward filter's state at
    the poses it rejects is a runaway prediction and the backward one, from the poses
    after them, is on the pose's side. Without a pose: the forward state. The status and
    innovation stay the forward filter's."""
    if pose is None:
        return forward
    R, t_mm, cov = pose

    def d2(state: RelativeState) -> float:
        d = np.concatenate(
            [Rotation.from_matrix(R @ state.R.T).as_rotvec(), np.asarray(t_mm) - state.t_mm]
        )
        try:
            return float(d @ np.linalg.solve(cov + state.covariance[:6, :6], d))
        except np.linalg.LinAlgError:
            return float("inf")

    if d2(backward) < d2(forward):
        return replace(
            backward,
            status=forward.status,
            innovation_d2=forward.innovation_d2,
            n_rejected=forward.n_rejected,
        )
    return forward


def agree(
    forward: RelativeState, backward: RelativeState, difference: np.ndarray | None = None
) -> bool:
    """Whether a frame's two estimates of the pose are within ``FUSION_GATE_CHI2`` of
    each other under the sum of their covariances; ``difference`` as ``fused``'s."""
    d = (_difference(forward, backward) if difference is None else difference)[:6]
    S = (forward.covariance + backward.covariance)[:6, :6]
    try:
        d2 = float(d @ np.linalg.solve(S, d))
    except np.linalg.LinAlgError:
        return False
    return d2 <= FUSION_GATE_CHI2


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
    time_s: Sequence[float],
    poses: Sequence[PoseOrNone],
    *,
    causal: bool = False,
    advance: Callable[[int], None] | None = None,
) -> list[RelativeState | None]:
    """``smoothed_states`` (all the poses), or with ``causal`` ``causal_states`` (the
    poses up to each frame), with the motion-model filter of ``tofpose estimate
    --filter``; ``advance`` as ``smoothed_states``'."""
    if causal:
        states = causal_states(time_s, poses)
        if advance is not None:
            advance(3 * len(states))  # the smoother's three passes' worth, at once
        return states
    return smoothed_states(time_s, poses, advance=advance)
