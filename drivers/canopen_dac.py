"""A CiA 401 analogue-output node: volts out by index, counts scaled from the module's own
objects, each set-point read back within one LSB (``docs/canopen-plan.md`` section 3).

The CANopen counterpart of ``drivers.can_dac.CanDac``: the same ``write``/``read``/``limits``,
so ``drivers.torquer`` and ``drivers.command`` put their channels on either. The set-point
limits are checked by the caller before ``write``; the counts' own range (16 bits) is checked
here, before any frame.
"""

from __future__ import annotations

import logging

from drivers import canopen_frames as cf
from drivers.calibration import RigCalibration
from drivers.can_dac import check_readback
from drivers.can_link import CanLink
from drivers.canopen_client import CanopenClient
from drivers.errors import ProtocolError, SetpointRangeError
from drivers.setpoints import SetpointLimits

log = logging.getLogger(__name__)

AO_16 = 0x6411           # write analogue output 16-bit (I16 counts)
AO_ERROR_MODE = 0x6443   # 1: the output takes its error value on a communication error
AO_ERROR_VALUE = 0x6444  # the error value, counts
AO_SI_UNIT = 0x6450      # CiA 303-2 unit of the output
AO_FULL_SCALE = 0x2100   # manufacturer: microvolts at 32768 counts
COUNTS_MIN, COUNTS_MAX = -32768, 32767


class CanopenDac:
    """The node ``name``'s ``outputs`` analogue outputs, with the rig's set-point limits."""

    def __init__(self, link: CanLink, name: str, outputs: int, calibration: RigCalibration | None = None) -> None:
        self.limits = SetpointLimits(calibration or RigCalibration())
        self.outputs = outputs
        subs = range(1, outputs + 1)
        self.node = CanopenClient(
            link, name, cf.DEVICE_TYPE_401_AO, raw_index=AO_16,
            safe_values=[((AO_16, s), 0) for s in subs],
            configure=[*(((AO_ERROR_MODE, s), 1) for s in subs), *(((AO_ERROR_VALUE, s), 0) for s in subs)])
        self._lsb_V: list[float] | None = None

    # ------------------------------------------------------------------ scaling
    def lsb_V(self, index: int) -> float:
        """Volts per count of output ``index``, from the module (read once)."""
        if self._lsb_V is None:
            self._lsb_V = [self._read_lsb(s) for s in range(1, self.outputs + 1)]
        return self._lsb_V[index]

    def _read_lsb(self, sub: int) -> float:
        unit = self.node.read(AO_SI_UNIT, sub, what=f"read SI unit of output {sub}")
        if unit != cf.SI_VOLT:
            raise ProtocolError(f"CAN node '{self.node.name}' output {sub} is in SI unit 0x{unit:08x}, "
                                f"not volts (0x{cf.SI_VOLT:08x}); set the module up per its EDS")
        full_uV = self.node.read_if_present(AO_FULL_SCALE, sub, what=f"read full scale of output {sub}")
        if full_uV is None:
            full_uV = self.node.eds_default(AO_FULL_SCALE, sub)
            log.info("CAN node '%s' has no full-scale object: +-%g V from its EDS", self.node.name, full_uV * 1e-6)
        if full_uV <= 0:
            raise ProtocolError(f"CAN node '{self.node.name}' output {sub}: full scale {full_uV} uV is not positive")
        return full_uV * 1e-6 / 32768

    def counts(self, index: int, volts: float) -> int:
        """Counts for ``volts`` on output ``index``; refused, nothing sent, beyond 16 bits."""
        lsb = self.lsb_V(index)
        lo, hi = COUNTS_MIN * lsb, 32768 * lsb
        if not lo <= volts <= hi:
            raise SetpointRangeError(f"CAN node '{self.node.name}' output {index + 1}: {volts:+.6f} V is beyond the "
                                     f"module's range {lo:+.6f}..{hi:+.6f} V; nothing was sent", value=volts,
                                     limit=(lo, hi))
        return max(COUNTS_MIN, min(COUNTS_MAX, round(volts / lsb)))

    # ------------------------------------------------------------------ outputs
    def write(self, index: int, volts: float, what: str) -> float:
        """Set output ``index`` (already checked against the limits) by SDO; returns its read-back (V)."""
        counts = self.counts(index, volts)
        self.node.write(AO_16, index + 1, counts, what=f"{what} = {volts:+.6f} V ({counts} counts)")
        back = self.read(index, what)
        return check_readback(self.node, what, volts, back, self.lsb_V(index))

    def read(self, index: int, what: str) -> float:
        return self.node.read(AO_16, index + 1, what=f"read {what}") * self.lsb_V(index)
