"""A DAC node on the CAN bus: volts out by index, each set-point read back within one LSB.

The torquer DACs and the command DACs are both this (``drivers.torquer``, ``drivers.command``);
they differ in what their outputs are and which limits apply, which ``SetpointLimits`` checks
before ``write`` is called.
"""

from __future__ import annotations

from typing import Protocol

from drivers import can_protocol as cp
from drivers.calibration import RigCalibration
from drivers.can_link import CanLink, NodeClient
from drivers.errors import ProtocolError
from drivers.setpoints import SetpointLimits


class CanDac:
    """The node ``name``'s analogue outputs, with the rig's set-point limits."""

    def __init__(self, link: CanLink, name: str, calibration: RigCalibration | None = None) -> None:
        self.limits = SetpointLimits(calibration or RigCalibration())
        self.node = NodeClient(link, name)

    def write(self, index: int, volts: float, what: str) -> float:
        """Set output ``index`` (already checked against the limits); returns its read-back (V)."""
        back = cp.from_micro(self.node.call(cp.OP_SET, index, cp.to_micro(volts), what=f"{what} = {volts:+.6f} V"))
        return check_readback(self.node, what, volts, back, self.limits.calibration.dac_lsb_V)

    def read(self, index: int, what: str) -> float:
        return cp.from_micro(self.node.call(cp.OP_GET, index, what=f"read {what}"))


class _Node(Protocol):
    name: str
    link: CanLink


def check_readback(node: _Node, what: str, sent: float, back: float, lsb: float) -> float:
    """A DAC's read-back must equal the set-point within one LSB; anything else is a fault."""
    if abs(back - sent) > lsb * 1.001 + 1e-6:
        fault = ProtocolError(f"CAN node '{node.name}': {what} reads back {back:+.6f} V after setting "
                              f"{sent:+.6f} V (more than one LSB, {lsb * 1e3:.3f} mV, apart)")
        node.link.faults.report(fault)
        raise fault
    return back
