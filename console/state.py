"""What the rig thread knows, for the UI to draw (polled), and what it tells (posted).

State that changes continuously (relay status, read-backs, the recording's counters, a
procedure's progress) sits in ``LiveState``, which the rig thread replaces piece by piece and
the UI copies on its refresh timer. Outcomes that happen once (a command refused, a recording
closed, a fault) are posted as the small event objects below, which the app turns into
Textual messages.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field, replace
from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING, Any

from drivers.relay import RelayStatus
from drivers.rig_datasheet import RigCalibration

if TYPE_CHECKING:
    from procedures.runner import RunSummary


@dataclass(frozen=True)
class RecordingInfo:
    path: Path
    rate_hz: float
    channels: tuple[str, ...]
    elapsed_s: float = 0.0
    samples: int = 0
    gaps: int = 0
    lost: int = 0
    status: str = "recording"


@dataclass(frozen=True)
class ProcedureInfo:
    name: str
    step: str = "starting"
    index: int = 0
    n_steps: int = 0
    fraction: float = 0.0
    remaining_rig_s: float = 0.0
    remaining_wall_s: float | None = None
    file: Path | None = None
    aborting: bool = False
    #: the steps, or a phase after them ("analysing", ...): ``procedures.progress.Progress``
    phase: str = "steps"


class Phase(StrEnum):
    """What the console's rig thread is doing; ``LiveState.update`` allows only the moves in
    ``_NEXT`` (as bluesky's RunEngine guards its state machine)."""

    OPENING = "opening"  # the rig is being opened
    READY = "ready"  # meters running, commands accepted
    RECORDING = "recording"  # an operator's recording is open
    PROCEDURE = "procedure"  # a procedure owns the rig; only its abort is accepted
    FAULT = "fault"  # a device fault is latched; the rig went safe
    CLOSED = "closed"  # the thread has ended (quit, or the rig could not be opened)

    def can_become(self, other: Phase) -> bool:
        return other is self or other in _NEXT[self]


_NEXT: dict[Phase, frozenset[Phase]] = {
    Phase.OPENING: frozenset({Phase.READY, Phase.FAULT, Phase.CLOSED}),
    Phase.READY: frozenset({Phase.RECORDING, Phase.PROCEDURE, Phase.FAULT, Phase.CLOSED}),
    Phase.RECORDING: frozenset({Phase.READY, Phase.FAULT, Phase.CLOSED}),
    Phase.PROCEDURE: frozenset({Phase.READY, Phase.FAULT, Phase.CLOSED}),
    Phase.FAULT: frozenset({Phase.CLOSED}),
    Phase.CLOSED: frozenset(),
}


class PhaseError(RuntimeError):
    """A move of the console's state machine that ``Phase`` does not allow: a bug."""


@dataclass(frozen=True)
class Snapshot:
    phase: Phase = Phase.OPENING
    relay: RelayStatus | None = None
    alarm: str | None = None  # the alarm lamp's reason (disallowed mode, interlock)
    fault: str | None = None  # a latched device fault (the rig went safe)
    readback: dict[str, float] = field(default_factory=dict)  # torquer X.., vtd X.., gc X..
    caging: dict[str, bool] = field(default_factory=dict)
    slewing: dict[str, float] = field(default_factory=dict)  # channel -> target V
    recording: RecordingInfo | None = None
    procedure: ProcedureInfo | None = None
    last_file: Path | None = None
    rig_time_s: float = 0.0
    spin_left_s: float | None = None  # rig time until the wheels are at speed (estimated)


class LiveState:
    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._snap = Snapshot()

    def get(self) -> Snapshot:
        with self._lock:
            return self._snap

    def update(self, **changes: Any) -> Snapshot:
        with self._lock:
            new = changes.get("phase", self._snap.phase)
            if not self._snap.phase.can_become(new):
                raise PhaseError(f"the console cannot go from {self._snap.phase} to {new}")
            self._snap = replace(self._snap, **changes)
            return self._snap


# ---------------------------------------------------------------------------- posted events
@dataclass(frozen=True)
class RigReady:
    url: str
    calibration: RigCalibration
    channels: tuple[str, ...]
    virtual: bool


@dataclass(frozen=True)
class RigFailed:
    text: str


@dataclass(frozen=True)
class CommandOutcome:
    what: str
    ok: bool
    text: str


@dataclass(frozen=True)
class RecordingEnded:
    path: Path
    status: str
    samples: int
    gaps: int


@dataclass(frozen=True)
class ProcedureEnded:
    summary: RunSummary
    plots: tuple[Path, ...] = ()  # the report's plots, as written (read on the rig thread)


@dataclass(frozen=True)
class RigFault:
    text: str
    safe: str  # what the safe-state read-back said


@dataclass(frozen=True)
class WorkerStopped:
    reason: str
    safe: str
    closed: tuple[str, ...] = ()  # what the shutdown closed: "recording out/x.h5 (aborted: ...)"


@dataclass(frozen=True)
class RigEventItem:
    """A rig event (``Rig.subscribe``) or a console note, for the event log, with the rig's
    time (None where unknown) and the wall clock's (Unix s) when it was made."""

    rig_time_s: float | None
    kind: str
    text: str
    wall_s: float = field(default_factory=time.time)
