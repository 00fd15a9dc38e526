"""A CiA 401 analogue-output node: volts out by index, counts scaled from the module's own
objects, each set-point read back within one LSB (``docs/canopen-plan.md`` section 3).

``drivers.torquer`` and ``drivers.command`` put their channels on it. The set-point
limits are checked by the caller before ``write``; the counts' own range (16 bits) is checked
here, before any frame.
"""

from __future__ import annotations

import logging
import struct

from drivers import canopen_frames as cf
from drivers.can_link import CanLink
from drivers.canopen_client import CanopenClient
from drivers.errors import DeviceLost, DriverError, ProtocolError, SetpointRangeError
from drivers.rig_datasheet import RigCalibration
from drivers.setpoints import SetpointLimits

log = logging.getLogger(__name__)

AO_16 = 0x6411  # write analogue output 16-bit (I16 counts)
AO_ERROR_MODE = 0x6443  # 1: the output takes its error value on a communication error
AO_ERROR_VALUE = 0x6444  # the error value, counts
AO_SI_UNIT = 0x6450  # CiA 303-2 unit of the output
AO_FULL_SCALE = 0x2100  # manufacturer: microvolts at 32768 counts
RPDO_ASYNC = 255  # CiA 301 transmission type: a receive PDO acts on arrival
COUNTS_MIN, COUNTS_MAX = -32768, 32767


class CanopenDac:
    """The node ``name``'s ``outputs`` analogue outputs, with the rig's set-point limits."""

    def __init__(
        self, link: CanLink, name: str, outputs: int, calibration: RigCalibration | None = None
    ) -> None:
        self.limits = SetpointLimits(calibration or RigCalibration())
        self.outputs = outputs
        subs = range(1, outputs + 1)
        self.node = CanopenClient(
            link,
            name,
            cf.DEVICE_TYPE_401_AO,
            raw_index=AO_16,
            safe_values=[((AO_16, s), 0) for s in subs],
            configure=[
                *(((AO_ERROR_MODE, s), 1) for s in subs),
                *(((AO_ERROR_VALUE, s), 0) for s in subs),
            ],
        )
        self._lsb_V: list[float] | None = None
        #: the receive PDOs of the EDS: (COB-ID, [output index per mapped I16]); outputs as last
        #: sent by the host (counts), for the outputs a PDO carries but a stream does not change
        self.rpdos = self._rpdos()
        self._sent: dict[int, int] = {}
        #: outputs known as the module has them since the last set-point by SDO or ``confirm``:
        #: a stream's first PDO reads the others it carries again, so it never puts back a value
        #: the module no longer has (rebooted, or tripped to its error values, meanwhile)
        self._fresh: set[int] = set()

    # ------------------------------------------------------------------ scaling
    def read_scale(self) -> None:
        """Read every output's unit and full scale from the module (the rig does at connect, so
        a module not set up per its EDS stops the open: ``ProtocolError``)."""
        self._lsb_V = [self._read_lsb(s) for s in range(1, self.outputs + 1)]

    def lsb_V(self, index: int) -> float:
        """Volts per count of output ``index``, from the module (read once)."""
        if self._lsb_V is None:
            self.read_scale()
        assert self._lsb_V is not None
        return self._lsb_V[index]

    def _read_lsb(self, sub: int) -> float:
        unit = self.node.read_if_present(AO_SI_UNIT, sub, what=f"read SI unit of output {sub}")
        if unit is None:  # optional in CiA 401: the module is set up per its EDS
            unit = self.node.eds_default(AO_SI_UNIT, sub)
            log.info(
                "CAN node '%s' has no SI-unit object for output %d: 0x%08x from its EDS",
                self.node.name,
                sub,
                unit,
            )
        if unit != cf.SI_VOLT:
            raise ProtocolError(
                f"CAN node '{self.node.name}' output {sub} is in SI unit 0x{unit:08x}, "
                f"not volts (0x{cf.SI_VOLT:08x}); set the module up per its EDS"
            )
        full_uV = self.node.read_if_present(
            AO_FULL_SCALE, sub, what=f"read full scale of output {sub}"
        )
        if full_uV is None:
            full_uV = self.node.eds_default(AO_FULL_SCALE, sub)
            log.info(
                "CAN node '%s' has no full-scale object: +-%g V from its EDS",
                self.node.name,
                full_uV * 1e-6,
            )
        if full_uV <= 0:
            raise ProtocolError(
                f"CAN node '{self.node.name}' output {sub}: full scale {full_uV} uV is not positive"
            )
        return full_uV * 1e-6 / 32768

    def counts(self, index: int, volts: float) -> int:
        """Counts for ``volts`` on output ``index``; refused, nothing sent, beyond 16 bits."""
        lsb = self.lsb_V(index)
        lo, hi = COUNTS_MIN * lsb, 32768 * lsb
        if not lo <= volts <= hi:
            raise SetpointRangeError(
                f"CAN node '{self.node.name}' output {index + 1}: {volts:+.6f} V is beyond the "
                f"module's range {lo:+.6f}..{hi:+.6f} V; nothing was sent",
                value=volts,
                limit=(lo, hi),
            )
        return max(COUNTS_MIN, min(COUNTS_MAX, round(volts / lsb)))

    # ------------------------------------------------------------------ outputs
    def write(self, index: int, volts: float, what: str) -> float:
        """Set output ``index`` (already checked against the limits) by SDO; returns its read-back (V)."""
        counts = self.counts(index, volts)
        self._fresh.clear()
        self.node.write(AO_16, index + 1, counts, what=f"{what} = {volts:+.6f} V ({counts} counts)")
        self._sent[index] = counts
        back = self.read(index, what)
        return check_readback(self.node, what, volts, back, self.lsb_V(index))

    def read(self, index: int, what: str) -> float:
        counts = self.node.read(AO_16, index + 1, what=f"read {what}")
        self._sent[index] = counts
        return counts * self.lsb_V(index)

    # ------------------------------------------------------------------ receive PDOs (streams)
    def _rpdos(self) -> list[tuple[int, list[int]]]:
        out = []
        for n in range(4):
            if 0x1400 + n not in self.node.node.object_dictionary:
                break
            cob = self.node.eds_default(0x1400 + n, 1)
            mapped = []
            for s in range(1, self.node.eds_default(0x1600 + n, 0) + 1):
                entry = self.node.eds_default(0x1600 + n, s)
                index, sub, bits = entry >> 16, (entry >> 8) & 0xFF, entry & 0xFF
                if index != AO_16 or bits != 16:
                    raise ProtocolError(
                        f"CAN node '{self.node.name}': RPDO{n + 1} maps 0x{entry:08x}, not a "
                        f"16-bit analogue output; check its EDS"
                    )
                mapped.append(sub - 1)
            out.append((cob, mapped))
        return out

    def configure_rpdos(self) -> None:
        """Make the module's receive PDOs the EDS's (at connect): each one's COB-ID, transmission
        type and mapping is read; one that differs (a module with X and Y swapped, CiA 401's
        default mapping, a PDO left disabled) is rewritten per CiA 301 - disabled, mapping
        cleared, entries, count, enabled - and read back. A module that refuses, or keeps
        something else, is a ``ProtocolError`` naming what differs: a stream on a mapping the
        host does not know would drive the wrong output."""
        for n, (cob, mapped) in enumerate(self.rpdos):
            comm, mapping = 0x1400 + n, 0x1600 + n
            want = [(AO_16 << 16) | ((i + 1) << 8) | 16 for i in mapped]
            got = self._read_rpdo(comm, mapping)
            if self._rpdo_is(got, cob, want):
                continue
            found = self._rpdo_text(got)
            log.warning(
                "CAN node '%s': RPDO%d (%s) differs from its EDS; configuring it per the EDS",
                self.node.name,
                n + 1,
                found,
            )
            why = "does not keep"
            try:
                self.node.write(
                    comm, 1, cob | 0x80000000, what=f"disable RPDO{n + 1}", check_faults=False
                )
                self.node.write(
                    mapping, 0, 0, what=f"clear RPDO{n + 1} mapping", check_faults=False
                )
                for s, entry in enumerate(want, start=1):
                    self.node.write(
                        mapping, s, entry, what=f"map RPDO{n + 1} entry {s}", check_faults=False
                    )
                self.node.write(
                    mapping, 0, len(want), what=f"RPDO{n + 1} mapping count", check_faults=False
                )
                self.node.write(
                    comm, 2, RPDO_ASYNC, what=f"RPDO{n + 1} transmission type", check_faults=False
                )
                self.node.write(comm, 1, cob, what=f"enable RPDO{n + 1}", check_faults=False)
                ok = self._rpdo_is(self._read_rpdo(comm, mapping), cob, want)
            except DriverError as exc:
                ok, why = False, f"refused its EDS mapping ({exc})"
            if not ok:
                fault = ProtocolError(
                    f"CAN node '{self.node.name}': RPDO{n + 1} {why}: it has {found}; the EDS "
                    f"has COB-ID 0x{cob:03x}, maps {', '.join(f'0x{e:08x}' for e in want)}. "
                    f"Set the module up per its EDS"
                )
                self.node.link.faults.report(fault)
                raise fault

    def _read_rpdo(self, comm: int, mapping: int) -> tuple[int, int | None, list[int]]:
        """The module's RPDO as it has it: COB-ID, transmission type (None: no such object),
        mapping entries."""
        cob = self.node.read(comm, 1, what=f"read RPDO COB-ID 0x{comm:04x}", check_faults=False)
        kind = self.node.read_if_present(comm, 2, what=f"read RPDO transmission type 0x{comm:04x}")
        count = self.node.read(
            mapping, 0, what=f"read RPDO mapping count 0x{mapping:04x}", check_faults=False
        )
        entries = [
            self.node.read(
                mapping, s, what=f"read RPDO mapping 0x{mapping:04x}:{s}", check_faults=False
            )
            for s in range(1, min(count, 8) + 1)
        ]
        return cob, kind, entries

    @staticmethod
    def _rpdo_is(got: tuple[int, int | None, list[int]], cob: int, want: list[int]) -> bool:
        got_cob, kind, entries = got
        return got_cob & 0x800007FF == cob and kind in (None, 254, RPDO_ASYNC) and entries == want

    @staticmethod
    def _rpdo_text(got: tuple[int, int | None, list[int]]) -> str:
        cob, _, entries = got
        return f"COB-ID 0x{cob:08x}, maps {', '.join(f'0x{e:08x}' for e in entries) or 'nothing'}"

    def stream(self, index: int, volts: float, what: str) -> float:
        """Set output ``index`` (already checked against the limits) by its receive PDO: one
        frame, unconfirmed, for a stream of set-points (a bias slew, an excitation's V_Td, a
        sweep's gamma_c): a quarter of an SDO download's host time, and no answer to wait for.
        Returns the volts the counts stand for; ``confirm`` reads every streamed output back."""
        self.node.link.faults.check()
        counts = self.counts(index, volts)
        cob, mapped = next(((c, m) for c, m in self.rpdos if index in m), (0, []))
        if not mapped:
            raise ProtocolError(
                f"CAN node '{self.node.name}': output {index + 1} ({what}) is on no receive PDO"
            )
        for i in mapped:  # the PDO carries its other outputs as they are
            if i != index and i not in self._fresh:
                self.read(i, f"output {i + 1}")
                self._fresh.add(i)
        self._sent[index] = counts
        self._fresh.add(index)
        data = struct.pack(f"<{len(mapped)}h", *(self._sent[i] for i in mapped))
        try:
            self.node.link.network.send_message(cob, data)
        except (OSError, ValueError) as exc:  # can.CanError is an OSError
            fault = DeviceLost(
                f"CAN {self.node.link.channel}: cannot send RPDO 0x{cob:03x} to node "
                f"'{self.node.name}' ({exc}); is the interface up?"
            )
            self.node.link.faults.report(fault)
            raise fault from exc
        return counts * self.lsb_V(index)

    def confirm(self) -> None:
        """Read back, by SDO, every output a stream set: each must be what was sent (a lost
        or refused PDO is a ``ProtocolError``, latched)."""
        self._fresh.clear()
        for index, counts in sorted(self._sent.items()):
            got = self.node.read(AO_16, index + 1, what=f"read back output {index + 1}")
            if got != counts:
                fault = ProtocolError(
                    f"CAN node '{self.node.name}': output {index + 1} reads back {got} counts "
                    f"after the stream sent {counts} (a receive PDO lost, or the node not "
                    f"operational)"
                )
                self.node.link.faults.report(fault)
                raise fault


def check_readback(node: CanopenClient, what: str, sent: float, back: float, lsb: float) -> float:
    """A DAC's read-back must equal the set-point within one LSB; anything else is a fault."""
    if abs(back - sent) > lsb * 1.001 + 1e-6:
        fault = ProtocolError(
            f"CAN node '{node.name}': {what} reads back {back:+.6f} V after setting "
            f"{sent:+.6f} V (more than one LSB, {lsb * 1e3:.3f} mV, apart)"
        )
        node.link.faults.report(fault)
        raise fault
    return back
