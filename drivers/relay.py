"""The relay driver: the six modes, switched as on the thesis's console (II C.2 (2), Ch. II D).

The operator holds the mode register, sets the select switches and releases: the register
clocks the selected mode in only on release, and never clocks modes 0 or 7 (the alarm
lights instead). Modes 4 and 5 need the gyros at speed and caged.

For the open-loop baselines (Ch. V B) the relay node also clamps the platform to the table and
opens the power-amplifier drive to the gimbal motors (``clamp``/``unclamp``). Clamping is
allowed in modes 1-3 only, with every command input (V_Td, gamma_c) at zero; modes 4-6 are
refused while clamped; releasing needs the command inputs at zero. The node enforces these;
the driver checks them first and says what to do. The safe state never moves the clamp.
"""

from __future__ import annotations

import abc
import logging
from collections.abc import Callable
from dataclasses import dataclass

from drivers import rig_nodes as rn
from drivers.can_link import CanLink
from drivers.canopen_client import ABORT_INTERLOCK, CanopenClient
from drivers.errors import DriverError, InterlockError, ModeNotAllowed
from drivers.rig_datasheet import GYRO_CHANNELS

log = logging.getLogger(__name__)

MODES = {
    1: "gyro off",
    2: "gyro spin-up",
    3: "autocollimator control",
    4: "gyro control, 4-channel caging",
    5: "gyro control, 3-channel caging",
    6: "external",
}
#: Gyro channels that must be caged before each gyro-control mode (mode 5 cages all but Z).
CAGED_FOR_MODE = {4: ("X", "Y", "Z", "XRD"), 5: ("X", "Y", "XRD")}
SAFE_MODE = 1


@dataclass(frozen=True)
class RelayStatus:
    mode: int
    selected: int
    held: bool
    alarm: bool
    at_speed: dict[str, bool]
    caged: dict[str, bool]
    spin_fraction: float  # slowest wheel, fraction of operating speed
    clamped: bool = False  # platform clamped to the table, motor drive open (Ch. V B)


def check_mode(mode: object) -> int:
    if isinstance(mode, bool) or not isinstance(mode, int) or mode not in MODES:
        raise ModeNotAllowed(mode)  # type: ignore[arg-type]
    return mode


#: modes the platform may be clamped in
CLAMP_MODES = rn.CLAMP_MODES
UNCLAMP_HINT = "release it with `fbs clamp off --rig URL`"


def interlock_reason(mode: int, status: RelayStatus) -> str | None:
    """Why ``mode`` may not be entered now (None if it may)."""
    if status.clamped and mode not in CLAMP_MODES:
        return (
            f"mode {mode} refused: platform clamped (loops open; modes 1-3 only while clamped); "
            f"{UNCLAMP_HINT}"
        )
    if mode not in CAGED_FOR_MODE:
        return None
    why = []
    if not all(status.at_speed.values()):
        slow = [c for c, ok in status.at_speed.items() if not ok]
        why.append(
            f"gyros not at speed ({', '.join(slow)}; wheels at {100 * status.spin_fraction:.0f} % "
            f"of operating speed; spin up in mode 2)"
        )
    uncaged = [c for c in CAGED_FOR_MODE[mode] if not status.caged[c]]
    if uncaged:
        why.append(
            f"gyro channel(s) {', '.join(uncaged)} not caged (mode {status.mode}; cage in mode 3 "
            f"with caging not inhibited and the pickoffs at null)"
        )
    return f"mode {mode} refused: " + "; ".join(why) if why else None


class RelayDriver(abc.ABC):
    #: Reason the last selection was refused (the console's alarm lamp), or None.
    alarm: str | None = None
    #: called with the mode in force whenever the driver learns it (a release, a status read)
    mode_seen: Callable[[int], None] | None = None

    def _seen(self, mode: int) -> int:
        if self.mode_seen is not None:
            self.mode_seen(mode)
        return mode

    @abc.abstractmethod
    def hold(self) -> None: ...

    @abc.abstractmethod
    def select(self, mode: int) -> None: ...

    @abc.abstractmethod
    def release(self) -> int:
        """Clock the selection in; returns the mode now in force."""

    @abc.abstractmethod
    def status(self) -> RelayStatus: ...

    @abc.abstractmethod
    def _set_clamp(self, clamped: bool) -> bool:
        """Send the clamp request; returns the node's read-back."""

    def clamp(self, commands_zero: bool = True) -> bool:
        """Clamp the platform to the table and open the motor drive (Ch. V B). Refused, before
        anything is sent, outside modes 1-3 or with a command input not at zero (the caller
        reads the command DACs back: ``Rig.clamp`` does)."""
        st = self.status()
        if st.clamped:
            return True
        why = []
        mode = st.selected if st.held else st.mode
        if mode not in CLAMP_MODES:
            why.append(f"mode {mode} (clamp in modes 1-3 only: switch to mode 3 first)")
        if not commands_zero:
            why.append("a command input (V_Td or gamma_c) is not at zero (set it to 0 V first)")
        if why:
            raise InterlockError("clamp refused: " + "; ".join(why), reasons=tuple(why))
        return self._set_clamp(True)

    def unclamp(self, commands_zero: bool = True) -> bool:
        """Release the clamp (the loops close again); refused with a command input not at zero."""
        if not commands_zero:
            why = "a command input (V_Td or gamma_c) is not at zero (set it to 0 V first)"
            raise InterlockError(f"unclamp refused: {why}", reasons=(why,))
        if not self.status().clamped:
            return False
        return self._set_clamp(False)

    def _checked(self, mode: object) -> int:
        """``check_mode``, lighting the alarm on a disallowed mode."""
        try:
            return check_mode(mode)
        except ModeNotAllowed as exc:
            self.alarm = str(exc)
            raise

    def set_mode(self, mode: int) -> int:
        """Hold, select, release, with the interlocks checked first; returns the new mode."""
        mode = self._checked(mode)
        why = interlock_reason(mode, self.status())
        if why:
            self.alarm = why
            raise InterlockError(why)
        self.hold()
        try:
            self.select(mode)
        except BaseException:
            try:
                self.release()  # a refused selection leaves the register as it was
            except DriverError as exc:
                log.warning("release after a refused selection failed: %s", exc)
            raise
        now = self.release()
        self.alarm = None
        return now


#: the relay node's manufacturer objects (docs/canopen-plan.md section 5, drivers/eds/relay.eds)
R_MODE, R_SWITCHES, R_SELECTED, R_REASONS, R_STATUS, R_CLAMP, R_SAFE = range(0x2000, 0x2007)
SWITCH_HOLD, SWITCH_RELEASE = 1, 2
#: the reason bits of 0x2003, spelled out
REASONS = (
    (rn.WHY_NOT_AT_SPEED, "gyros not at speed"),
    (rn.WHY_NOT_CAGED, "gyros not caged"),
    (rn.WHY_CLAMPED, f"platform clamped; {UNCLAMP_HINT}"),
    (rn.WHY_MODE, "mode outside 1-3"),
    (rn.WHY_COMMAND, "a command input not at zero"),
)


def decode_status(w: int) -> RelayStatus:
    """The relay node's status word (object 0x2004, docs/protocol.md 2.5)."""
    return RelayStatus(
        mode=(w >> rn.ST_MODE_SHIFT) & 7,
        selected=(w >> rn.ST_SELECT_SHIFT) & 7,
        held=bool(w & rn.ST_HELD),
        alarm=bool(w & rn.ST_ALARM),
        at_speed={
            c: bool(w >> (rn.ST_AT_SPEED_SHIFT + i) & 1) for i, c in enumerate(GYRO_CHANNELS)
        },
        caged={c: bool(w >> (rn.ST_CAGED_SHIFT + i) & 1) for i, c in enumerate(GYRO_CHANNELS)},
        spin_fraction=((w >> rn.ST_SPIN_SHIFT) & 0xFF) / 100.0,
        clamped=bool(w & rn.ST_CLAMPED),
    )


class CanopenRelayDriver(RelayDriver):
    """The relay driver node over CANopen: the same hold/select/release, interlocks, alarm and
    clamp, in the node, behind manufacturer objects; a refusal is an SDO abort, its reasons
    in 0x2003."""

    def __init__(self, link: CanLink) -> None:
        self.node = CanopenClient(
            link, "relay", 0, raw_index=R_MODE, safe_values=[((R_SAFE, 0), 1)]
        )

    def hold(self) -> None:
        self.node.write(R_SWITCHES, 0, SWITCH_HOLD, what="HOLD")

    def select(self, mode: int) -> None:
        mode = self._checked(mode)
        self.node.write(R_SELECTED, 0, mode, what=f"SELECT mode {mode}")

    def release(self) -> int:
        self._refined(lambda: self.node.write(R_SWITCHES, 0, SWITCH_RELEASE, what="RELEASE"))
        return self._seen(self.node.read(R_MODE, 0, what="read the mode"))

    def _set_clamp(self, clamped: bool) -> bool:
        what = "CLAMP" if clamped else "UNCLAMP"
        self._refined(lambda: self.node.write(R_CLAMP, 0, int(clamped), what=what))
        return bool(self.node.read(R_CLAMP, 0, what="read the clamp"))

    def _refined(self, write: Callable[[], None]) -> None:
        """Run ``write``; an interlock refusal is raised with the node's reasons spelled out."""
        try:
            write()
        except InterlockError as exc:
            if exc.detail != ABORT_INTERLOCK:
                raise
            bits = self.node.read(R_REASONS, 0, what="read the interlock reasons")
            why = tuple(w for b, w in REASONS if bits & b)
            raise InterlockError(
                f"{exc}" + (f" ({'; '.join(why)})" if why else ""), reasons=why, detail=bits
            ) from None

    def status(self) -> RelayStatus:
        st = decode_status(self.node.read(R_STATUS, 0, what="STATUS"))
        self._seen(st.mode)
        return st
