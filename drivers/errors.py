"""Typed driver faults. Every fault says what was wrong, on which device, and what to do.

``DriverError`` is the base; catch it to catch any rig fault. ``SetpointRangeError`` and
``InterlockError`` are raised *before* any byte is sent; the others report what the wire or
the device did.
"""

from __future__ import annotations


class DriverError(Exception):
    """Base of every rig fault."""


class DeviceTimeout(DriverError):
    """A device did not answer (or stopped streaming) within its time limit."""


class ProtocolError(DriverError):
    """Bytes that do not follow the protocol: bad CRC, bad length, unknown reply, bad frame.

    ``kind`` names the class of damage where the decoder knows it (e.g. "bad CRC"), else "".
    """

    def __init__(self, message: str, *, kind: str = "") -> None:
        super().__init__(message)
        self.kind = kind


class SetpointRangeError(DriverError, ValueError):
    """A set-point or configuration value outside what the device or the rig allows.

    Raised before anything is sent; ``value`` and ``limit`` name the offence.
    """

    def __init__(self, message: str, *, value: object = None, limit: object = None) -> None:
        super().__init__(message)
        self.value = value
        self.limit = limit


class InterlockError(DriverError):
    """The rig refuses the request in its present state (mode interlocks, node latched safe).

    ``reasons`` says why in words, one per interlock that holds (e.g. "gyros not at speed");
    ``detail`` is the node's raw refusal word (its interlock bits), 0 when it gave none.
    """

    def __init__(self, message: str, *, reasons: tuple[str, ...] = (), detail: int = 0) -> None:
        super().__init__(message)
        self.reasons = tuple(reasons)
        self.detail = detail


class PlatformClamped(InterlockError):
    """The platform is clamped to the table with its motor drive open (the open-loop baseline's
    state, Ch. V B): a procedure that needs the stabilization loops closed refuses to start."""

    def __init__(self, what: str) -> None:
        super().__init__(
            f"{what}: platform clamped (loops open); release it with `fbs clamp off --rig URL` "
            f"(the command inputs at zero), then start again",
            reasons=("platform clamped",),
        )


class ModeNotAllowed(InterlockError, ValueError):
    """Modes 0 and 7 do not exist on the relay driver; selecting one lights the alarm."""

    def __init__(self, mode: int) -> None:
        super().__init__(
            f"mode {mode} is not allowed (modes 1-6 only; 0 and 7 are disallowed and "
            f"light the alarm); the rig stays in its present mode"
        )
        self.mode = mode


class DeviceLost(DriverError):
    """A device stopped talking (pulled cable, dead node, closed port). The rig has gone safe."""


class RigBusy(DriverError):
    """Another host holds the rig (its lock, its ADC port, or its heartbeat on the CAN bus).
    Raised before this host sent any byte: the other host's session is untouched."""


class NodeReset(DeviceLost):
    """A CAN node rebooted on its own and lost its set-points. The rig has gone safe."""


class NodeError(DriverError):
    """A CAN node reported an error of its own (an emergency frame)."""

    def __init__(self, message: str, *, node: str = "", code: int = 0) -> None:
        super().__init__(message)
        self.node = node
        self.code = code


class SampleGap(DriverError):
    """ADC samples were lost on the way. The stream goes on after the gap; it is never spliced.

    ``start`` and ``stop`` are sample indices since the stream's start: samples
    ``start <= i < stop`` are missing. ``reason`` says how the loss was detected.
    """

    def __init__(self, start: int, stop: int, reason: str) -> None:
        super().__init__(
            f"ADC samples {start}..{stop - 1} lost ({stop - start} sample sets): {reason}"
        )
        self.start = start
        self.stop = stop
        self.reason = reason


class OperatorAbort(DriverError):
    """The operator declined a manual step (for example a rotary-table move)."""
