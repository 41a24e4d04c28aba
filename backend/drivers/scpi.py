"""Motion driver for an SCPI rate-table controller (ACUTROL3000-style command set) through
PyVISA (``pyvisa`` with the pure-Python ``pyvisa-py`` backend; install ``tofpose[scpi]``).

The resource is any VISA resource name; for a controller on the network that is
``TCPIP::host::port::SOCKET``, and GPIB or serial controllers work the same way. The
command set (docs/devices.md, "Rate-table protocol"): ``:MODE n,POS``,
``:INTerlock:CLOSe n``, ``:DEMand:POSition n,deg``, ``:READ:POSition? n``, ``:STATus? n``,
``:ABORt``, limits with ``:LIMit:POSition:LOW? n`` / ``HIGH?`` / ``:LIMit:VELocity? n``,
errors from ``:SYSTem:ERRor?``.

Policy:

- Every command that changes state is followed by ``:SYSTem:ERRor?``; a non-zero answer
  raises ``MotionError`` naming the command and the controller's message.
- Before a move, the driver puts each axis it moves in position mode and closes its
  interlock (as an operator's software does); a fault or an open safety interlock is
  reported, never overridden.
- ``stop`` goes out on a session of its own, opened at connect time, so it never waits
  behind a query in flight on the command session.
- Any I/O error or time-out closes the session; the next call reconnects (the server
  meanwhile shows the motion system degraded).
"""

from __future__ import annotations

import contextlib
import re
import threading
from typing import Any

from backend.drivers.base import AxisLimits, MotionError, MotionStatus

DEFAULT_AXIS_NUMBERS = {"yaw": 1, "pitch": 2, "roll": 3, "rail": 4}
STATUS_IN_MOTION = 2
STATUS_IN_POSITION = 4
STATUS_ABORTED = 32
_ERROR_AT_END = re.compile(r'(?:^|;)(?P<code>[+-]?\d+),"(?P<message>[^"]*)"$')


def _visa() -> Any:
    try:
        import pyvisa
    except ImportError as exc:  # pragma: no cover - the extra is part of dev installs
        raise MotionError(
            "the scpi motion driver needs PyVISA: pip install 'tofpose[scpi]'"
        ) from exc
    return pyvisa


class ScpiRateTable:
    """A rate table behind an SCPI controller (implements ``MotionDriver``).

    resource : VISA resource name, e.g. ``TCPIP::127.0.0.1::5025::SOCKET``.
    axis_numbers : {axis name: controller axis number}; axes the controller does not
        have (its limit query fails) are left out.
    timeout_s : I/O time-out of each command.
    """

    name = "scpi"

    def __init__(
        self,
        resource: str,
        *,
        axis_numbers: dict[str, int] | None = None,
        timeout_s: float = 2.0,
        visa_library: str = "@py",
    ) -> None:
        self.resource = resource
        self.timeout_s = timeout_s
        self._rm = _visa().ResourceManager(visa_library)
        self._lock = threading.Lock()
        self._stop_lock = threading.Lock()
        self._session: Any = None
        self._stop_session: Any = None
        self.identity = ""
        self._connect()
        self.axis_numbers, self.axes = self._read_axes(axis_numbers or DEFAULT_AXIS_NUMBERS)
        if not self.axes:
            raise MotionError(f"{resource}: the controller reports none of the axes asked for")

    # -- link ---------------------------------------------------------------------------
    def _open(self) -> Any:
        pyvisa = _visa()
        try:
            inst = self._rm.open_resource(
                self.resource,
                read_termination="\n",
                write_termination="\n",
                timeout=int(self.timeout_s * 1000),
            )
        except (pyvisa.errors.VisaIOError, OSError, ValueError) as exc:
            raise MotionError(f"cannot open {self.resource}: {exc}") from exc
        return inst

    def _connect(self) -> None:
        self._session = self._open()
        self._stop_session = self._open()
        try:
            self.identity = self._query_raw(self._session, "*CLS;*IDN?")
        except MotionError as exc:
            raise MotionError(
                f"cannot reach the rate-table controller at {self.resource}: {exc.__cause__}"
            ) from exc

    def _drop(self) -> None:
        for inst in (self._session, self._stop_session):
            if inst is not None:
                # closing a dead link may fail; it is gone either way
                with contextlib.suppress(Exception):
                    inst.close()
        self._session = self._stop_session = None

    def _ensure(self) -> Any:
        if self._session is None:
            self._drop()
            self._connect()
        return self._session

    def _query_raw(self, inst: Any, text: str) -> str:
        pyvisa = _visa()
        try:
            return str(inst.query(text)).strip()
        except (pyvisa.errors.VisaIOError, OSError, ConnectionError) as exc:
            self._drop()
            raise MotionError(f"{self.resource}: no answer to {text!r}: {exc}") from exc

    def _exchange(self, inst: Any, text: str) -> list[str]:
        """Send ``text`` with an error-queue query in the same message; return the answers
        of its queries, or raise ``MotionError`` with the controller's error."""
        reply = self._query_raw(inst, f"{text};:SYST:ERR?")
        m = _ERROR_AT_END.search(reply)
        if m is None:
            raise MotionError(f"{self.resource}: unreadable reply {reply!r} to {text!r}")
        if int(m["code"]) != 0:
            self._query_raw(inst, "*CLS;*OPC?")  # one error is enough to report
            raise MotionError(f"the controller refused {text!r}: {m['code']} {m['message']}")
        head = reply[: m.start()]
        return head.split(";") if head else []

    def query(self, text: str) -> list[str]:
        """Queries (``;``-joined) on the command session, reconnecting first if the link
        was lost; returns their answers."""
        with self._lock:
            return self._exchange(self._ensure(), text)

    def command(self, text: str) -> None:
        """State-changing commands, checked against the controller's error queue."""
        self.query(text)

    # -- axes ---------------------------------------------------------------------------
    def _read_axes(self, wanted: dict[str, int]) -> tuple[dict[str, int], dict[str, AxisLimits]]:
        numbers, axes = {}, {}
        for name, n in wanted.items():
            try:
                low, high, vel, unit = self.query(
                    f":LIM:POS:LOW? {n};:LIM:POS:HIGH? {n};:LIM:VEL? {n};:UNIT? {n}"
                )
            except MotionError:  # the controller has no such axis
                if self._session is None:
                    raise
                continue
            numbers[name] = n
            axes[name] = AxisLimits(name, unit.strip().lower(), float(low), float(high),
                                    float(vel))  # fmt: skip
        return numbers, axes

    # -- MotionDriver -------------------------------------------------------------------
    def move_to(self, setpoints: dict[str, float]) -> None:
        with self._lock:
            inst = self._ensure()
            for name in setpoints:
                n = self.axis_numbers[name]
                mode, closed = self._exchange(inst, f":MODE? {n};:INT? {n}")
                if closed.strip() != "1":
                    self._exchange(inst, f":INT:CLOS {n}")
                if mode.strip().upper() != "POS":
                    self._exchange(inst, f":MODE {n},POS")
            for name, value in setpoints.items():
                self._exchange(inst, f":DEM:POS {self.axis_numbers[name]},{value:.6f}")

    def stop(self) -> None:
        """Abort every axis, on the stop session (never queued behind another command)."""
        with self._stop_lock:
            inst = self._stop_session
            if inst is None:
                with self._lock:
                    self._drop()
                    self._connect()
                inst = self._stop_session
            self._exchange(inst, ":ABOR")

    def status(self) -> MotionStatus:
        query = ";".join(
            f":READ:POS? {n};:DEM:POS? {n};:STAT? {n}" for n in self.axis_numbers.values()
        )
        parts = self.query(query)
        if len(parts) != 3 * len(self.axis_numbers):
            raise MotionError(f"{self.resource}: status reply has {len(parts)} fields")
        positions, targets, busy, settled, stopped = {}, {}, False, True, False
        for i, name in enumerate(self.axis_numbers):
            pos, target, bits = parts[3 * i : 3 * i + 3]
            positions[name], targets[name] = float(pos), float(target)
            b = int(bits)
            busy |= bool(b & STATUS_IN_MOTION)
            settled &= bool(b & STATUS_IN_POSITION)
            stopped |= bool(b & STATUS_ABORTED)
        return MotionStatus(positions, targets, busy, settled and not busy, stopped)

    def reset_faults(self) -> None:
        """Clear the controller's axis faults (the operator's acknowledgement after the
        cause is fixed); interlocks stay open until the next move closes them."""
        self.command(";".join(f":FAUL:CLE {n}" for n in self.axis_numbers.values()))

    def describe(self) -> dict[str, str]:
        """Model, firmware and link state for GET /api/devices."""
        parts = [p.strip() for p in self.identity.split(",")] + ["", "", "", ""]
        return {
            "model": f"{parts[0]} {parts[1]}".strip(),
            "firmware": parts[3],
            "link": "up" if self._session is not None else "down",
            "address": self.resource,
        }

    def close(self) -> None:
        with self._lock:
            self._drop()
        with contextlib.suppress(Exception):  # it may already be gone at shutdown
            self._rm.close()
