"""The rate-table emulator on the wire: SCPI parsing, the error queue, interlocks, safety,
faults and bad input, spoken to over a raw socket as any SCPI client would."""

from __future__ import annotations

import contextlib
import socket
import time

import pytest

from backend.drivers.sim import make_sim_world
from backend.emulators.rate_table import (
    STATUS_ABORTED,
    STATUS_INTERLOCK_CLOSED,
    STATUS_SAFETY_OPEN,
    RateTableEmulator,
)
from backend.emulators.scpi_parse import ScpiError, match_node, parse_command, split_message


class Client:
    def __init__(self, address) -> None:
        self.sock = socket.create_connection(address, timeout=3)
        self.f = self.sock.makefile("rwb")

    def send(self, line: str | bytes) -> None:
        self.f.write((line.encode() if isinstance(line, str) else line) + b"\n")
        self.f.flush()

    def ask(self, line: str) -> str:
        self.send(line)
        return self.f.readline().decode().strip()

    def close(self) -> None:
        self.sock.close()


@pytest.fixture
def emu():
    with RateTableEmulator(make_sim_world(time_scale=20.0), port=0) as e:
        yield e


@pytest.fixture
def c(emu):
    client = Client(emu.address)
    yield client
    client.close()


def test_scpi_node_forms():
    assert match_node("DEM", "DEMand") and match_node("demand", "DEMand")
    assert not match_node("DEMA", "DEMand")
    assert split_message(':a 1;:b "x;y";*IDN?') == [":a 1", ':b "x;y"', "*IDN?"]
    cmd = parse_command(":demand:pos? 2", {("DEMand", "POSition"): "x"})
    assert cmd.path == ("DEMAND", "POSITION") and cmd.query and cmd.args == ("2",)
    with pytest.raises(ScpiError) as e:
        parse_command(":dem:posx 1", {("DEMand", "POSition"): "x"})
    assert e.value.code == -113


def test_identity_limits_and_units(c):
    assert "ACUTROL3000" in c.ask("*IDN?")
    assert c.ask(":LIMIT:POSITION:LOW? 1;:lim:pos:high? 1;:unit? 1;:unit? 4") == (
        "-170.000000;170.000000;DEG;MM"
    )


def test_move_needs_interlock_and_position_mode(emu, c):
    c.send(":dem:pos 1,10")
    assert c.ask(":syst:err?").startswith("201,")  # interlock open
    c.send(":int:clos 1")
    c.send(":dem:pos 1,10")
    assert c.ask(":syst:err?").startswith("204,")  # not in position mode
    assert c.ask(":syst:err?") == '0,"No error"'
    assert abs(float(c.ask(":read:pos? 1"))) < 0.01  # nothing moved
    c.send(":mode 1,pos;:dem:pos 1,10")
    assert c.ask(":syst:err?") == '0,"No error"'
    time.sleep(0.2)  # 20x lab time: the 10 deg move takes < 1.5 lab-s
    assert float(c.ask(":read:pos? 1")) == pytest.approx(10.0, abs=0.01)
    assert int(c.ask(":stat? 1")) & STATUS_INTERLOCK_CLOSED


def test_safety_interlock_stops_and_refuses_until_closed(emu, c):
    c.send(":int:clos 2;:mode 2,pos;:dem:pos 2,50")
    time.sleep(0.05)
    emu.controller.set_safety_open(True)
    stopped_at = float(c.ask(":read:pos? 2"))
    assert 0 < stopped_at < 50
    bits = int(c.ask(":stat? 2"))
    assert bits & STATUS_SAFETY_OPEN and bits & STATUS_ABORTED
    assert not bits & STATUS_INTERLOCK_CLOSED  # the safety chain dropped the drive
    c.send(":int:clos 2")
    assert c.ask(":syst:err?") == '202,"Safety interlock open"'
    c.send(":sim:safety clos;:int:clos 2;:dem:pos 2,0")
    assert c.ask(":syst:err?") == '0,"No error"'


def test_fault_blocks_its_axis_until_cleared(c):
    c.send(':sim:faul 3,"encoder lost"')
    assert c.ask(":faul? 3") == '1,"encoder lost"'
    c.send(":int:clos 3")
    assert c.ask(":syst:err?") == '203,"Axis fault; encoder lost"'
    c.send(":faul:cle 3;:int:clos 3;:mode 3,pos;:dem:pos 3,5")
    assert c.ask(":syst:err?") == '0,"No error"'


@pytest.mark.parametrize(
    ("line", "code", "names"),
    [
        (":dem:pos 1,999", -222, "outside [-170, 170]"),
        (":dem:pos 9,1", -222, "no axis 9"),
        (":dem:pos one,1", -104, "axis must be an integer"),
        (":dem:pos 1,nan", -222, "not finite"),
        (":dem:pos 1", -109, "Missing parameter"),
        (":abort 1", -108, "Parameter not allowed"),
        (":mode 1,rate", -221, "not modelled"),
        (":mode 1,fly", -224, "mode 'FLY'"),
        (":frobnicate 1", -113, "Undefined header"),
        (":read:pos 1", -113, "query only"),
        (":lim:pos:low 1,-500", -222, "beyond the hardware range"),
        (":lim:pos:low 1,171", -222, "beyond the hardware range"),
        (":synt:sine 4,5,0.25,1", -221, "rotary axes"),
        (":synt:sine 1,5,0.25,1.5", -104, "whole number"),
        (":synt:sine 1,5,0,1", -222, "frequency 0 Hz"),
        (":synt:sine 1,-5,0.25,1", -222, "amplitude_deg must be > 0"),
        (":synt:ramp 1,0,40,1", -222, "rate_deg_s must be finite and not 0"),
        (":synt:ramp 1,5,40", -109, "Missing parameter"),
        (":synt:stat 1", -113, "query only"),
    ],
)
def test_bad_commands_are_queued_errors_naming_the_problem(c, line, code, names):
    c.send(line)
    reply = c.ask(":syst:err?")
    assert reply.startswith(f"{code},") and names in reply, reply
    assert c.ask("*IDN?")  # the session goes on


def test_bad_bytes_do_not_kill_the_session(c):
    c.send(b"\xff\xfe:abort")
    assert c.ask(":syst:err?").startswith("-101,")
    c.send(b":" + b"x" * 5000)
    assert c.ask(":syst:err?").startswith("-363,")
    for _ in range(20):
        c.send(":nonsense")
    assert c.ask(":syst:err?").startswith("-113,")
    errors = [c.ask(":syst:err?") for _ in range(16)]
    assert '-350,"Queue overflow"' in errors and errors[-1] == '0,"No error"'


def test_narrowed_limits_refuse_moves_beyond_them(c):
    c.send(":lim:pos:high 1,20;:int:clos 1;:mode 1,pos;:dem:pos 1,30")
    assert c.ask(":syst:err?").startswith("-222,")
    assert c.ask(":lim:pos:high? 1") == "20.000000"


def test_close_drops_connected_clients(emu, c):
    emu.close()
    c.sock.settimeout(2)
    with contextlib.suppress(ConnectionResetError):  # a reset: gone as well
        assert c.sock.recv(10) == b""  # EOF: the link is gone


def test_synthesis_runs_a_loaded_sine_about_the_axis_position(emu, c):
    assert c.ask(":lim:acc? 1;:lim:vel? 1") == "40.000000;20.000000"
    assert c.ask(":synt? 1") == "NONE"
    c.send(":int:clos 1;:mode 1,pos;:dem:pos 1,10")
    time.sleep(0.2)
    c.send(":synt:sine 1,5,0.25,2")  # 5 deg, 0.25 Hz (4 s), 2 full cycles: 16 lab-s
    assert c.ask(":synt? 1") == "SINE,5.000000,0.25,2"
    c.send(":synt:star 1")
    assert c.ask(":syst:err?").startswith("205,")  # not in synthesis mode
    c.send(":mode 1,synt;:synt:star 1")
    assert c.ask(":syst:err?") == '0,"No error"'
    time.sleep(0.1)
    kind, elapsed, remaining = c.ask(":synt:stat? 1").split(",")
    assert kind == "SINE" and float(elapsed) + float(remaining) == pytest.approx(16.0)
    assert int(c.ask(":stat? 1")) & 2  # in motion
    running = emu.controller.world.bench.turntable.running_profile(emu.controller.world.now_s())
    assert running[0] == "yaw" and running[1].profile.start_deg == pytest.approx(10.0, abs=1e-3)
    c.send(":mode 1,pos")  # a running function is only ended by ABORt (or its end)
    assert c.ask(":syst:err?") == '207,"Synthesis function running; ABORt it first"'
    c.send(":synt:ramp 1,5,40,1")
    assert c.ask(":syst:err?").startswith("207,")
    assert c.ask(":synt:stat? 2") == "IDLE"
    c.send(":abor")
    assert c.ask(":synt:stat? 1") == "IDLE" and int(c.ask(":stat? 1")) & STATUS_ABORTED


def test_synthesis_refuses_what_the_table_cannot_follow(c):
    c.send(":synt:star 1")
    assert c.ask(":syst:err?").startswith("201,")  # interlock open, checked first
    c.send(":int:clos 1;:mode 1,synt;:synt:star 1")
    assert c.ask(":syst:err?") == '206,"No synthesis function loaded"'
    c.send(":synt:sine 1,10,0.5,1;:synt:star 1")  # 31 deg/s, 99 deg/s^2
    reply = c.ask(":syst:err?")
    assert reply.startswith("-222,") and "rate limit of 20" in reply, reply
    assert "acceleration limit of 40" in reply
    c.send(":lim:pos:high 1,3;:synt:ramp 1,5,40,1;:synt:star 1")  # 5.6 deg of travel
    reply = c.ask(":syst:err?")
    assert reply.startswith("-222,") and "soft limits [-170, 3]" in reply, reply
    assert c.ask(":synt:stat? 1") == "IDLE" and abs(float(c.ask(":read:pos? 1"))) < 0.01


def test_a_controller_without_synthesis_has_none_of_its_commands():
    with RateTableEmulator(make_sim_world(), port=0, synthesis=False) as emu:
        c = Client(emu.address)
        try:
            c.send(":synt:stat? 1")
            assert c.ask(":syst:err?").startswith("-113,")
            c.send(":mode 1,synt")
            reply = c.ask(":syst:err?")
            assert reply == '-221,"Settings conflict; this controller has no synthesis mode"'
            assert c.ask(":mode? 1") == "OFF"
        finally:
            c.close()
