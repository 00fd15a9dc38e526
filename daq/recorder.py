"""Record the rig's ADC stream into an "fbs-run" file (drivers -> daq -> HDF5).

Lost samples are never spliced over: the file keeps one time base from t = 0, the missing
samples are NaN, and a ``gap`` event gives their exact positions and the reason. Rig events
(mode changes, set-points, faults, the safe state) land in ``/events`` on the file's time
base. The file streams in SWMR mode with a flush at least every ``flush_s`` (``RunWriter``);
blocks are read ``block_s`` at a time, so a sample is on disk at most about
``2 block_s + flush_s`` (0.7 s by default) after it was taken.

Any exception (a device fault, Ctrl-C, a full disk) puts the rig in the safe state, closes
the file "aborted: <why>" and is raised again. The file is created before the ADC starts, so
an unwritable path fails before anything moves.
"""

from __future__ import annotations

import datetime as _dt
import logging
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from fbs.drivers.errors import DriverError, SampleGap
from fbs.drivers.rig import Rig

from .runfile import RunFileError, RunWriter, abort_status

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


def record(rig: Rig, path: str | Path, *, duration_s: float, rate_hz: float,
           channels: list[str] | tuple[str, ...] | None = None,
           ranges_V: Mapping[str, float] | float | None = None, block_s: float = 0.1, flush_s: float = 0.5,
           procedure: str | None = None, meta: Mapping[str, Any] | None = None,
           overwrite: bool = False) -> RecordResult:
    if not duration_s > 0:
        raise ValueError(f"record duration {duration_s!r} s must be > 0")
    channels = tuple(channels or rig.adc.identity.channels)
    cfg = rig.adc.configure(channels, rate_hz, ranges_V)
    total = int(round(duration_s * cfg.rate_hz))
    per = max(1, int(round(block_s * cfg.rate_hz)))
    mode = rig.relays.status().mode
    meta = dict(meta or {}) | {"adc": {"channels": list(cfg.channels), "rate_hz": cfg.rate_hz,
                                       "ranges_V": cfg.ranges_V, "identity": rig.adc.identity.__dict__}}
    writer = RunWriter(path, rig=rig.url, mode=mode, rate_hz=cfg.rate_hz, channels=dict.fromkeys(channels, "V"),
                       procedure=procedure, meta=meta, overwrite=overwrite, flush_s=flush_s)
    result = RecordResult(Path(path), 0, cfg.rate_hz, "recording")
    pending: list[tuple[float, str, str]] = []
    lock = threading.Lock()
    t0 = 0.0  # rig time of sample 0, set by start() before the listener is subscribed

    def on_event(t: float, kind: str, text: str) -> None:  # any thread; written by the loop
        with lock:
            pending.append((t - t0, kind, text))

    def flush_events() -> None:
        with lock:
            items, pending[:] = list(pending), []
        for e in items:
            writer.event(*e)

    status = "complete"
    try:
        t0 = rig.adc.start()
        rig.subscribe(on_event)
        writer.set_meta("acquisition", _start_stamp(rig, t0))
        writer.event(0.0, "start", f"recording {len(channels)} channels at {cfg.rate_hz:g} Hz, mode {mode}")
        pos = 0
        while pos < total:
            try:
                block = rig.adc.read(min(per, total - pos))
            except SampleGap as gap:
                stop = min(gap.stop, total)
                writer.append_missing(stop - pos)
                writer.event(gap.start / cfg.rate_hz, "gap", str(gap))
                result.gaps.append((gap.start, gap.stop, gap.reason))
                pos = stop
                continue
            writer.append(block.volts)
            over = block.overrange.any(axis=0)
            for j in np.flatnonzero(over):
                k = int(block.overrange[:, j].argmax())
                writer.event((block.first_sample + k) / cfg.rate_hz, "overrange",
                             f"{channels[j]}: {int(block.overrange[:, j].sum())} samples at full scale")
            pos = block.stop_sample
            flush_events()
        rig.adc.stop()
        result.samples = pos
        flush_events()
        writer.close(status)
    except BaseException as exc:
        status = abort_status(exc)
        _go_safe(rig, exc)
        raise
    finally:
        rig.unsubscribe(on_event)
        if rig.adc.streaming and rig.faults.fault is None:
            try:
                rig.adc.stop()
            except DriverError as exc:
                log.warning("stopping the ADC after an abort failed: %s", exc)
        if writer.is_open:
            try:
                if writer.failed is None:
                    flush_events()
            except RunFileError as exc:
                log.error("events after the abort were not written: %s", exc)
            finally:
                writer.close(status)
        result.samples = result.samples or writer.samples
        result.status = status
    return result


def _start_stamp(rig: Rig, t0: float) -> dict[str, Any]:
    """When sample 0 was taken: rig time, and wall-clock time unless the rig's time is virtual."""
    stamp: dict[str, Any] = {"start_rig_s": t0, "clock": "virtual" if rig.clock.virtual else "wall"}
    start = rig.clock.unix_time(t0)
    if start is not None:
        stamp["start_unix_s"] = start
        stamp["start_utc"] = _dt.datetime.fromtimestamp(start, _dt.timezone.utc).isoformat(timespec="microseconds")
    return stamp


def _go_safe(rig: Rig, exc: BaseException) -> None:
    """Every abort leaves the rig safe (mode 1, biases zero), whatever stopped the recording."""
    if isinstance(exc, RunFileError):
        log.error("%s; putting the rig in the safe state", exc)
    report = rig.safe()
    if not report.ok:
        log.error("the rig did not confirm the safe state: %s", "; ".join(report.failed))
