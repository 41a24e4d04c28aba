"""The TOFcam-660 emulator, spoken to by ESPROS's own client (``epc.tofCam660``,
unmodified) and over raw sockets for what a client must never send."""

from __future__ import annotations

import socket
import struct
import time

import numpy as np
import pytest

from backend.drivers.sim import make_sim_world
from backend.emulators.tofcam660 import (
    LOW_AMPLITUDE,
    MARKER_END,
    MARKER_START,
    NAK,
    SATURATION,
    CameraState,
    TofCam660Emulator,
    encode_frame,
    frame_message,
    packetise,
)

ADDRESS = "127.0.0.2"  # a loopback address of its own: the ports are fixed


@pytest.fixture
def world():
    w = make_sim_world(start_rail_mm=13000.0)  # 2 m range
    w.set_sensor(noise=False)  # deterministic frames: the emulator's equal a direct render
    return w


@pytest.fixture
def emu(world):
    with TofCam660Emulator(world, ADDRESS) as e:
        yield e


@pytest.fixture
def vendor(emu):
    from epc.tofCam660 import TOFcam660

    cam = TOFcam660(ADDRESS)
    yield cam
    cam.tcpInterface.close()
    cam.rxInterface.close()


def test_vendor_client_connects_initialises_and_reads_device_info(vendor):
    assert vendor.device.get_fw_version() == "3.59"
    vendor.initialize()  # every command the client sends on connect and initialize()
    assert vendor.device.get_chip_infos() == (56, 1234)
    assert vendor.device.get_chip_temperature() == pytest.approx(42.0)
    assert vendor.settings.get_integration_time()["lowIntTime"] == 16  # initialize()'s


def test_vendor_client_images_are_the_simulators_frame(world, vendor):
    vendor.settings.set_modulation(6)
    vendor.settings.set_integration_time(300)
    vendor.settings.set_minimal_amplitude(10)
    dist, amp = vendor.get_distance_and_amplitude()
    gray = vendor.get_grayscale_image()
    _, truth, *_ = world.capture()  # the same static scene, rendered directly
    assert dist.shape == amp.shape == gray.shape == (240, 320)
    valid = np.isfinite(truth.distance_mm)
    assert valid.sum() > 500  # reflectors and plate; the far wall is below min amplitude
    np.testing.assert_array_equal(dist[valid], np.rint(truth.distance_mm[valid]))
    assert np.all(dist[~valid] >= LOW_AMPLITUDE)
    np.testing.assert_array_equal(amp, truth.gray)  # no saturation at 300 us, 2 m
    np.testing.assert_array_equal(gray, truth.gray)
    # the reflectors are where the simulator put them: its brightest blobs
    assert (amp > 1000).sum() == (truth.gray > 1000).sum() > 50


def test_roi_and_modulation_change_the_frame(world, vendor):
    vendor.settings.set_roi((40, 20, 280, 220))
    dist, amp = vendor.get_distance_and_amplitude()
    assert dist.shape == (200, 240)
    vendor.settings.set_modulation(24)  # 6.25 m unambiguous range: 2 m still inside
    assert world.bench.sensor.modulation_frequency_hz == 24e6
    vendor.settings.set_integration_time(1234)
    assert world.bench.sensor.integration_time_us == 1234


def test_refused_parameters_are_error_responses(vendor):
    with pytest.raises(RuntimeError, match="Error"):
        vendor.settings.set_roi((0, 10, 400, 230))  # wider than the sensor
    with pytest.raises(RuntimeError, match="Error"):
        vendor.settings.set_integration_time(60000)
    vendor.settings.captureMode = 1  # streaming: not modelled, refused
    from epc.tofCam660 import Command

    with pytest.raises(RuntimeError, match="Error"):
        vendor.tcpInterface.transceive(Command.create("getDistance", 1))
    assert vendor.device.get_fw_version() == "3.59"  # the link goes on


class Raw:
    def __init__(self) -> None:
        self.sock = socket.create_connection((ADDRESS, 50660), timeout=5)

    def response(self) -> bytes:
        head = self._exact(8)
        start, n = struct.unpack("!II", head)
        assert start == MARKER_START
        payload = self._exact(n)
        assert struct.unpack("!I", self._exact(4))[0] == MARKER_END
        return payload

    def _exact(self, n: int) -> bytes:
        buf = b""
        while len(buf) < n:
            part = self.sock.recv(n - len(buf))
            assert part, "connection closed"
            buf += part
        return buf

    def command(self, cmd_id: int, data: bytes = b"") -> bytes:
        payload = struct.pack("!H", cmd_id) + data
        self.sock.sendall(frame_message(payload + bytes(34 - len(payload))))
        return self.response()


FIRMWARE = 37


@pytest.mark.parametrize(
    ("what", "wire"),
    [
        ("unknown command id", frame_message(struct.pack("!H", 999) + bytes(32))),
        (
            "wrong start marker",
            struct.pack("!II", 0x12345678, 34) + bytes(34) + struct.pack("!I", MARKER_END),
        ),
        (
            "wrong end marker",
            struct.pack("!II", MARKER_START, 34) + bytes(34) + struct.pack("!I", 0xDEADBEEF),
        ),
        ("oversized length", struct.pack("!II", MARKER_START, 1 << 30)),
        ("short payload", frame_message(b"\x00")),
        ("truncated message", struct.pack("!II", MARKER_START, 34) + bytes(10)),
    ],
)
def test_bad_bytes_on_the_wire_get_a_nak_and_the_link_goes_on(emu, what, wire):
    raw = Raw()
    raw.sock.sendall(wire)
    t0 = time.monotonic()
    assert raw.response() == bytes([NAK]), what
    if what == "truncated message":
        assert time.monotonic() - t0 >= 0.9  # waited for the rest, then gave up
    reply = raw.command(FIRMWARE)
    assert reply == bytes([2]) + struct.pack("!HH", 3, 59)
    raw.sock.close()


def test_a_client_that_vanishes_mid_message_does_not_stop_the_camera(emu):
    raw = Raw()
    raw.sock.sendall(struct.pack("!II", MARKER_START, 34) + bytes(5))
    raw.sock.close()
    assert Raw().command(FIRMWARE)[0] == 2


def test_frame_encoding_codes_and_packets():
    gray = np.array([[10, 4095], [300, 20]], np.uint16)
    dist = np.array([[1000.4, np.nan], [np.nan, 70000.0]], np.float32)
    frame = encode_frame(0, dist, gray, CameraState())
    pixels = np.frombuffer(frame[25:], "<u2").reshape(2, 2, 2)
    assert pixels[..., 0].tolist() == [[1000, SATURATION], [LOW_AMPLITUDE, 63999]]
    assert pixels[..., 1].tolist() == [[10, SATURATION], [300, 20]]
    big = bytes(range(256)) * 20
    packets = packetise(big, 7)
    assert len(packets) == 4 and all(len(p) <= 20 + 1400 for p in packets)
    reassembled = bytearray(len(big))
    for p in packets:
        mid, total, size, offset, count, number = struct.unpack("!HIHIII", p[:20])
        assert (mid, total, count) == (7, len(big), 4)
        reassembled[offset : offset + size] = p[20:]
    assert bytes(reassembled) == big
