"""The rotary table: tilt 0-90 deg about an east-west axis, spindle rotation (Ch. II B).

In the thesis the table is cranked by hand: ``ManualTable`` asks the operator (console or
terminal) and waits for the confirmed angle. ``CanopenTable`` is a motorized table (the
simulated rig's), commanded over CANopen; it reports when it is in position.
"""

from __future__ import annotations

import abc
import logging
import math
import sys
from collections.abc import Callable
from dataclasses import dataclass

from drivers import rig_nodes as rn
from drivers.can_link import CanLink
from drivers.canopen_client import CanopenClient
from drivers.clock import RigClock
from drivers.errors import DeviceTimeout, DriverError, OperatorAbort, SetpointRangeError
from drivers.setpoints import check_value

log = logging.getLogger(__name__)

TILT_LIMITS_DEG = (0.0, 90.0)


@dataclass(frozen=True)
class TablePosition:
    tilt_deg: float
    spindle_deg: float


def check_target(
    tilt_deg: float | None, spindle_deg: float | None
) -> tuple[float | None, float | None]:
    tilt = (
        None
        if tilt_deg is None
        else check_value(
            "table tilt (deg)",
            tilt_deg,
            TILT_LIMITS_DEG[1],
            "the table tilts 0..90 deg",
            lo=TILT_LIMITS_DEG[0],
        )
    )
    spindle = None
    if spindle_deg is not None:
        spindle = (
            check_value("table spindle angle (deg)", spindle_deg, 1e6, "a finite angle") % 360.0
        )
    return tilt, spindle


class RotaryTable(abc.ABC):
    @abc.abstractmethod
    def move_to(
        self, tilt_deg: float | None = None, spindle_deg: float | None = None
    ) -> TablePosition:
        """Move (or have the operator move) the table; returns the position in force."""

    @abc.abstractmethod
    def position(self) -> TablePosition: ...


#: An operator: shown a request, returns the answer typed (or clicked) in reply.
Operator = Callable[[str], str]


def terminal_operator(prompt: str) -> str:
    """Ask at the terminal. Without a terminal there is no operator: say so instead of hanging."""
    if not sys.stdin or not sys.stdin.isatty():
        raise OperatorAbort(
            f"the rotary table is manual and needs an operator, but there is no terminal "
            f"(request was: {prompt}); run interactively or use a motorized table"
        )
    return input(prompt + "\n> ")


class ManualTable(RotaryTable):
    """A hand-cranked table. The operator confirms each move, or types the angle actually set."""

    def __init__(
        self, operator: Operator = terminal_operator, start: TablePosition = TablePosition(0.0, 0.0)
    ) -> None:
        self.operator = operator
        self._pos = start

    def move_to(self, tilt_deg=None, spindle_deg=None) -> TablePosition:
        tilt, spindle = check_target(tilt_deg, spindle_deg)
        want = TablePosition(
            self._pos.tilt_deg if tilt is None else tilt,
            self._pos.spindle_deg if spindle is None else spindle,
        )
        if want == self._pos:
            return want
        answer = self.operator(
            f"Set the rotary table to tilt {want.tilt_deg:.4f} deg, spindle {want.spindle_deg:.4f} deg. "
            f"Press Enter when done, or type the spindle angle actually set, or 'abort'."
        ).strip()
        if answer.lower() in ("abort", "a", "q", "quit"):
            raise OperatorAbort("the operator aborted the rotary-table move")
        if answer:
            try:
                got = float(answer)
            except ValueError:
                raise SetpointRangeError(
                    f"operator's answer {answer!r} is not an angle in degrees", value=answer
                ) from None
            if not math.isfinite(got):
                raise SetpointRangeError(
                    f"operator's answer {answer!r} is not a finite angle", value=answer
                )
            want = TablePosition(want.tilt_deg, got % 360.0)
        log.info(
            "table at tilt %.4f deg, spindle %.4f deg (operator confirmed)",
            want.tilt_deg,
            want.spindle_deg,
        )
        self._pos = want
        return want

    def position(self) -> TablePosition:
        return self._pos


#: the table node's manufacturer objects (docs/canopen-plan.md section 6, drivers/eds/table.eds)
T_TILT, T_SPINDLE, T_ACTUAL_TILT, T_ACTUAL_SPINDLE, T_MOVING = range(0x2200, 0x2205)


class CanopenTable(RotaryTable):
    """A motorized table node over CANopen: targets 0x2200/0x2201, actual 0x2202/0x2203 (micro-
    degrees), moving 0x2204; the move is complete when moving reads 0."""

    def __init__(self, link: CanLink, clock: RigClock, move_timeout_s: float = 120.0) -> None:
        self.node = CanopenClient(link, "table", 0)
        self.clock = clock
        self.move_timeout_s = move_timeout_s

    def move_to(self, tilt_deg=None, spindle_deg=None) -> TablePosition:
        tilt, spindle = check_target(tilt_deg, spindle_deg)
        for index, value, what in ((T_TILT, tilt, "tilt"), (T_SPINDLE, spindle, "spindle")):
            if value is not None:
                self.node.write(index, 0, rn.to_micro(value), what=f"table {what} {value:.6f} deg")
        t_end = self.clock.now() + self.move_timeout_s
        while self.node.read(T_MOVING, 0, what="read table moving flag"):
            if self.clock.now() > t_end:
                fault: DriverError = DeviceTimeout(
                    f"rotary table not in position after {self.move_timeout_s:g} s of rig time"
                )
                self.node.link.faults.report(fault)
                raise fault
            self.clock.sleep(0.1)
        pos = self.position()
        for got, value in ((pos.tilt_deg, tilt), (pos.spindle_deg, spindle)):
            if value is not None and abs((got - value + 180.0) % 360.0 - 180.0) > 1e-3:
                fault = DriverError(
                    f"rotary table stopped at {got:.6f} deg, commanded {value:.6f} deg"
                )
                self.node.link.faults.report(fault)
                raise fault
        return pos

    def position(self) -> TablePosition:
        return TablePosition(
            rn.from_micro(self.node.read(T_ACTUAL_TILT, 0, what="read table tilt")),
            rn.from_micro(self.node.read(T_ACTUAL_SPINDLE, 0, what="read table spindle")),
        )
