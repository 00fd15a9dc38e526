"""What the rig thread knows, for the UI to draw (polled), and what it tells (posted).

State that changes continuously (relay status, read-backs, the recording's counters, a
procedure's progress) sits in ``LiveState``, which the rig thread replaces piece by piece and
the UI copies on its refresh timer. Outcomes that happen once (a command refused, a recording
closed, a fault) are posted as the small event objects below, which the app turns into
Textual messages.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from drivers.calibration import RigCalibration
from drivers.relay import RelayStatus


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


@dataclass(frozen=True)
class Snapshot:
    phase: str = "opening"                     # opening | ready | recording | procedure | fault | closed
    relay: RelayStatus | None = None
    alarm: str | None = None                   # the alarm lamp's reason (disallowed mode, interlock)
    fault: str | None = None                   # a latched device fault (the rig went safe)
    readback: dict[str, float] = field(default_factory=dict)   # torquer X.., vtd X.., gc X..
    caging: dict[str, bool] = field(default_factory=dict)
    slewing: dict[str, float] = field(default_factory=dict)    # channel -> target V
    recording: RecordingInfo | None = None
    procedure: ProcedureInfo | None = None
    last_file: Path | None = None
    rig_time_s: float = 0.0


class LiveState:
    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._snap = Snapshot()

    def get(self) -> Snapshot:
        with self._lock:
            return self._snap

    def update(self, **changes: Any) -> Snapshot:
        with self._lock:
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
    summary: Any              # procedures.runner.RunSummary


@dataclass(frozen=True)
class RigFault:
    text: str
    safe: str                 # what the safe-state read-back said


@dataclass(frozen=True)
class WorkerStopped:
    reason: str
    safe: str


@dataclass(frozen=True)
class RigEventItem:
    """A rig event (``Rig.subscribe``) or a console note, for the event log."""

    rig_time_s: float | None
    kind: str
    text: str
