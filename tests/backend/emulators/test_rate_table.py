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
