"""Latency statistics and frame accounting from known inputs: medians, 95th percentiles,
the sliding window, the drop counts, and the drivers' stamp arithmetic (the pacer's
skipped slots, the TOFcam-660's 16-bit counter, a replay's playback clock)."""

from __future__ import annotations

import numpy as np
import pytest

from backend.drivers.pacing import FramePacer
from backend.drivers.replay import PlaybackClock
from backend.drivers.tofcam660 import MeasurementIdUnwrap
from backend.services.live.latency import (
    ClockAnchor,
    FrameStamps,
    LatencySummary,
    LiveStatistics,
    SequenceGaps,
)

MS = 1_000_000  # ns


def _stamps(capture_ms: float, to_arrival_ms: float, to_pose_ms: float) -> FrameStamps:
    c = int(capture_ms * MS)
    return FrameStamps(c, c + int(to_arrival_ms * MS), c + int(to_pose_ms * MS))


def test_summary_of_known_values():
    # 1..20 ms: median halfway between 10 and 11; p95 at rank 0.95 * 19 = 18.05,
    # i.e. 19 + 0.05 * (20 - 19)
    s = LatencySummary.of(np.arange(1.0, 21.0))
    assert s.median_ms == pytest.approx(10.5)
    assert s.p95_ms == pytest.approx(19.05)
    assert s.n == 20
    assert LatencySummary.of(np.array([7.0])) == LatencySummary(7.0, 7.0, 1)
    assert LatencySummary.of(np.array([])) == LatencySummary(None, None, 0)


def test_window_latencies_and_drop_counts():
    stats = LiveStatistics(window_s=1.0, anchor=ClockAnchor(0, 1_700_000_000_000_000_000))
    sequences = [1, 2, 5, 6, 9, 10]  # 3-4 and 7-8 lost by the camera: 4 frames
    skipped = [0, 1, 0, 3, 0, 0]  # pipeline: 4 frames
    gaps = []
    for i, (seq, skip) in enumerate(zip(sequences, skipped, strict=True)):
        # capture every 100 ms; arrival 5 ms later; pose 10, 20, ..., 60 ms after capture
        gaps.append(
            stats.record_frame(
                _stamps(100.0 * i, 5.0, 10.0 * (i + 1)), sequence=seq, slots_skipped=skip
            )
        )
    assert gaps == [(0, 0), (0, 1), (2, 0), (0, 3), (2, 0), (0, 0)]
    stats.record_client_drops(2, now_ns=250 * MS)
    for i, sent_ms in enumerate([30.0, 40.0]):  # frames 0 and 1 sent 30 and 40 ms after capture
        st = _stamps(100.0 * i, 5.0, 10.0 * (i + 1))
        stats.record_sent(st, st.capture_ns + int(sent_ms * MS))
    snap = stats.snapshot(now_ns=600 * MS)
    assert snap.frames_in_window == 6 and snap.frames_total == 6
    assert snap.capture_to_arrival == LatencySummary(5.0, 5.0, 6)
    assert snap.capture_to_pose.median_ms == pytest.approx(35.0)  # of 10..60
    assert snap.capture_to_pose.p95_ms == pytest.approx(57.5)  # 50 + 0.75 * 10
    assert snap.capture_to_sent.median_ms == pytest.approx(35.0)
    assert snap.dropped_total.camera == 4 and snap.dropped_total.pipeline == 4
    assert snap.dropped_total.clients == 2
    assert snap.dropped_in_window == snap.dropped_total
    # at 1.3 s only frames that arrived in the last second remain: 3, 4, 5 (305-505 ms)
    late = stats.snapshot(now_ns=1_300 * MS)
    assert late.frames_in_window == 3
    assert late.capture_to_pose.median_ms == pytest.approx(50.0)
    assert late.dropped_in_window.camera == 2 and late.dropped_in_window.pipeline == 3
    assert late.dropped_in_window.clients == 0  # the client drops were at 250 ms
    assert late.capture_to_sent.n == 0 and late.capture_to_sent.median_ms is None
    assert late.dropped_total == snap.dropped_total  # totals never leave
    assert snap.anchor.wall_ns_of(2 * MS) == 1_700_000_000_000_000_000 + 2 * MS


def test_camera_without_a_counter_has_no_camera_count():
    stats = LiveStatistics()
    stats.record_frame(_stamps(0.0, 1.0, 2.0), sequence=None, slots_skipped=0)
    snap = stats.snapshot(now_ns=10 * MS)
    assert snap.dropped_total.camera is None and snap.dropped_in_window.camera is None


def test_sequence_gaps_and_restart():
    g = SequenceGaps()
    assert [g.observe(s) for s in (10, 11, 15, 2, 3, None, 5)] == [0, 0, 3, 0, 0, 0, 1]


@pytest.mark.parametrize(
    ("kwargs", "needle"), [({"window_s": 0.0}, "window_s"), ({"max_frames": 0}, "max_frames")]
)
def test_bad_settings_are_named(kwargs, needle):
    with pytest.raises(ValueError, match=needle):
        LiveStatistics(**kwargs)


def test_pacer_counts_the_slots_a_busy_reader_skipped():
    # at 10 Hz, releases at 0, 0.1, 0.35, 0.4, 1.05 s: slots 0, 1, 3, 4, 10
    p = FramePacer(10.0)
    assert [p._slots_skipped(t) for t in (5.0, 5.1, 5.35, 5.4, 6.05)] == [0, 0, 1, 0, 5]
    p.set_rate(20.0)  # a new period: counted afresh from the next release
    assert [p._slots_skipped(t) for t in (7.0, 7.05, 7.2)] == [0, 0, 2]


def test_tofcam_measurement_id_unwraps_across_16_bits():
    u = MeasurementIdUnwrap()
    assert [u.unwrap(i) for i in (65533, 65534, 65535, 1, 2)] == [0, 1, 2, 4, 5]
    assert u.unwrap(None) is None
    gaps = SequenceGaps()
    assert [gaps.observe(s) for s in (0, 1, 2, 4, 5)] == [0, 0, 0, 1, 0]  # id 0 was lost


def test_playback_clock_maps_recorded_stamps_and_reanchors():
    c = PlaybackClock(speed=2.0)  # played twice as fast as recorded
    period_s = 0.05
    assert c.capture_ns(10.0, 1_000 * MS, period_s) == 1_000 * MS  # the anchor
    # recorded 0.1 s later: 50 ms later in playback; released 3 ms after that
    assert c.capture_ns(10.1, 1_053 * MS, period_s) == 1_050 * MS
    # never after its release
    assert c.capture_ns(10.2, 1_090 * MS, period_s) == 1_090 * MS
    # released 400 ms late (a slow pipeline): anchored afresh
    assert c.capture_ns(10.3, 1_550 * MS, period_s) == 1_550 * MS
    assert c.capture_ns(10.4, 1_601 * MS, period_s) == 1_600 * MS
