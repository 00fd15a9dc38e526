"""Record the rig's ADC stream into an "fbs-run" file (drivers -> daq -> HDF5).

``Acquisition`` is one continuous recording that a procedure runs alongside its commands:
every second of rig time a procedure spends passes through ``acquire``, which reads the
ADC, writes the file and hands the samples back, so commands land between blocks and the
file's time base is the ADC's. ``record`` is the plain case: acquire for a duration.

Lost samples are never spliced over: the file keeps one time base from t = 0, the missing
samples are NaN, and a ``gap`` event gives their exact positions and the reason. Rig events
(mode changes, set-points, faults, the safe state) land in ``/events`` on the file's time
base. The file streams in SWMR mode with a flush at least every ``flush_s`` (``RunWriter``);
blocks are read ``block_s`` at a time, so a sample is on disk at most about
``2 block_s + flush_s`` (0.7 s by default) after it was taken.

Any exception (a device fault, Ctrl-C, a full disk) closes the file "aborted: <why>" and is
raised again. The recorder only records: driving the rig safe is the business of whoever
executes the run (``drivers.safety.SafeOnAbort``, which ``record`` and the procedure runner
wrap around their recordings). The file is created before the ADC starts, so an unwritable
path fails before anything moves.
"""

from __future__ import annotations

import datetime as _dt
import logging
import threading
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import Any

import numpy as np

from daq import provenance
from daq.runfile import STATUS_COMPLETE, STATUS_RECORDING, RunFileError, RunWriter, abort_status
from drivers.adc import AdcBlock
from drivers.errors import DriverError, SampleGap
from drivers.rig import Rig
from drivers.safety import SafeOnAbort

log = logging.getLogger(__name__)


@dataclass
class RecordResult:
    path: Path
    samples: int
    rate_hz: float
    status: str
    gaps: list[tuple[int, int, str]] = field(default_factory=list)

    @property
    def lost(self) -> int:
        return sum(stop - start for start, stop, _ in self.gaps)


class Acquisition:
    """The ADC streaming into one run file for as long as the ``with`` block lasts (or from
    ``start`` to ``close``, for a caller that holds a recording open across calls)."""

    def __init__(
        self,
        rig: Rig,
        path: str | Path,
        *,
        rate_hz: float,
        channels: list[str] | tuple[str, ...] | None = None,
        ranges_V: Mapping[str, float] | float | None = None,
        block_s: float = 0.1,
        flush_s: float = 0.5,
        procedure: str | None = None,
        axis: str | None = None,
        meta: Mapping[str, Any] | None = None,
        overwrite: bool = False,
        mode: int | None = None,
    ) -> None:
        self.rig = rig
        self.channels = tuple(channels or rig.adc.identity.channels)
        self.cfg = rig.adc.configure(self.channels, rate_hz, ranges_V)
        self.rate_hz = self.cfg.rate_hz
        self.block = max(1, int(round(block_s * self.rate_hz)))
        # The file's mode is the one the run is about (a procedure may start by switching to it).
        self.mode = rig.relays.status().mode if mode is None else mode
        meta = dict(meta or {}) | {
            "adc": {
                "channels": list(self.cfg.channels),
                "rate_hz": self.rate_hz,
                "ranges_V": self.cfg.ranges_V,
                "identity": rig.adc.identity.__dict__,
            }
        }
        # which rig, simulated or not, which software: every file says (daq.provenance)
        meta.setdefault("provenance", provenance.of_rig(rig))
        self.writer = RunWriter(
            path,
            rig=rig.url,
            mode=self.mode,
            rate_hz=self.rate_hz,
            channels=dict.fromkeys(self.channels, "V"),
            procedure=procedure,
            axis=axis,
            meta=meta,
            overwrite=overwrite,
            flush_s=flush_s,
        )
        self.result = RecordResult(Path(path), 0, self.rate_hz, STATUS_RECORDING)
        self.pos = 0  # samples acquired (the next sample's index)
        self.t0 = 0.0  # rig time of sample 0
        self._pending: list[tuple[float, str, str]] = []
        self._lock = threading.Lock()

    # ------------------------------------------------------------------ lifetime
    def start(self) -> Acquisition:
        """Start the ADC and the file's time base; on failure the file is closed "aborted"."""
        try:
            self.t0 = self.rig.adc.start()
            self.rig.subscribe(self._on_event)
            self.writer.set_meta("acquisition", _start_stamp(self.rig, self.t0))
            self.writer.event(
                0.0,
                "start",
                f"recording {len(self.channels)} channels at {self.rate_hz:g} Hz, mode {self.mode}",
            )
        except BaseException as exc:
            self.close(exc)
            raise
        return self

    def close(self, exc: BaseException | None = None) -> None:
        """Stop the ADC and close the file: "complete" without ``exc``, else "aborted: <why>".
        A failure while finishing a clean run is raised, and the file is closed "aborted"."""
        status = STATUS_COMPLETE
        try:
            if exc is None:
                self.rig.adc.stop()
                self._flush_events()
                self.writer.close(status)
        except BaseException as failure:  # a failure while finishing is an abort like any other
            exc = failure
            raise
        finally:
            if exc is not None:
                status = abort_status(exc)
            self._finish(status)

    def __enter__(self) -> Acquisition:
        return self.start()

    def __exit__(
        self, et: type[BaseException] | None, ev: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close(ev)

    def _finish(self, status: str) -> None:
        self.rig.unsubscribe(self._on_event)
        if self.rig.adc.streaming and self.rig.faults.fault is None:
            try:
                self.rig.adc.stop()
            except DriverError as exc:
                log.warning("stopping the ADC after an abort failed: %s", exc)
        if self.writer.is_open:
            try:
                if self.writer.failed is None:
                    self._flush_events()
            except RunFileError as exc:
                log.error("events after the abort were not written: %s", exc)
            finally:
                self.writer.close(status)
        self.result.samples = self.pos
        self.result.status = status

    # ------------------------------------------------------------------ events
    def _on_event(self, t: float, kind: str, text: str) -> None:  # any thread; written by the loop
        with self._lock:
            self._pending.append((t - self.t0, kind, text))

    def _flush_events(self) -> None:
        with self._lock:
            items, self._pending[:] = list(self._pending), []
        for e in items:
            self.writer.event(*e)

    def note(self, kind: str, text: str, time_s: float | None = None) -> None:
        """A procedure's event, at ``time_s`` on the file's time base (default: now)."""
        self.writer.event(self.time_s if time_s is None else time_s, kind, text)

    @property
    def time_s(self) -> float:
        """File time of the next sample."""
        return self.pos / self.rate_hz

    # ------------------------------------------------------------------ data
    def acquire(self, duration_s: float, *, keep: bool = True) -> np.ndarray | None:
        """Acquire ``duration_s`` of samples; with ``keep`` return them as (n, n_channels),
        lost samples NaN (as in the file)."""
        return self.acquire_samples(int(round(duration_s * self.rate_hz)), keep=keep)

    def acquire_samples(self, n: int, *, keep: bool = True) -> np.ndarray | None:
        out = np.empty((n, len(self.channels))) if keep else None
        base = self.pos
        end = base + n
        while self.pos < end:
            start = self.pos
            try:
                block = self.rig.adc.read(min(self.block, end - self.pos))
            except SampleGap as gap:
                stop = min(gap.stop, end)
                self.writer.append_missing(stop - start)
                self.writer.event(gap.start / self.rate_hz, "gap", str(gap))
                self.result.gaps.append((gap.start, gap.stop, gap.reason))
                if out is not None:
                    out[start - base : stop - base] = np.nan
                self.pos = stop
                continue
            self.writer.append(block.volts)
            if out is not None:
                out[start - base : block.stop_sample - base] = block.volts
            self._overrange_events(block)
            self.pos = block.stop_sample
            self._flush_events()
        return out

    def _overrange_events(self, block: AdcBlock) -> None:
        over = block.overrange.any(axis=0)
        for j in np.flatnonzero(over):
            k = int(block.overrange[:, j].argmax())
            self.writer.event(
                (block.first_sample + k) / self.rate_hz,
                "overrange",
                f"{self.channels[j]}: {int(block.overrange[:, j].sum())} samples at full scale",
            )


def record(
    rig: Rig,
    path: str | Path,
    *,
    duration_s: float,
    rate_hz: float,
    channels: list[str] | tuple[str, ...] | None = None,
    ranges_V: Mapping[str, float] | float | None = None,
    block_s: float = 0.1,
    flush_s: float = 0.5,
    procedure: str | None = None,
    meta: Mapping[str, Any] | None = None,
    overwrite: bool = False,
) -> RecordResult:
    """Record ``duration_s`` seconds of the ADC to ``path``; returns what was written. An abort
    leaves the rig safe (``SafeOnAbort``) and the file closed "aborted: <why>"."""
    if not (duration_s > 0 and duration_s < float("inf")):
        raise ValueError(f"record duration {duration_s!r} s must be a finite number > 0")
    guard = SafeOnAbort(rig, "recording")
    with guard:
        acq = Acquisition(
            rig,
            path,
            rate_hz=rate_hz,
            channels=channels,
            ranges_V=ranges_V,
            block_s=block_s,
            flush_s=flush_s,
            procedure=procedure,
            meta=meta,
            overwrite=overwrite,
        )
        with acq, guard:  # the inner guard first: the safe state lands in the file before it closes
            acq.acquire(duration_s, keep=False)
    return acq.result


def _start_stamp(rig: Rig, t0: float) -> dict[str, Any]:
    """When sample 0 was taken: rig time, and wall-clock time unless the rig's time is virtual."""
    stamp: dict[str, Any] = {"start_rig_s": t0, "clock": "virtual" if rig.clock.virtual else "wall"}
    start = rig.clock.unix_time(t0)
    if start is not None:
        stamp["start_unix_s"] = start
        stamp["start_utc"] = _dt.datetime.fromtimestamp(start, _dt.UTC).isoformat(
            timespec="microseconds"
        )
    return stamp
