"""Record the rig's ADC stream into an "fbs-run" file (drivers -> daq -> HDF5).

Lost samples are never spliced over: the file keeps one time base from t = 0, the missing
samples are NaN, and a ``gap`` event gives their exact positions and the reason. Rig events
(mode changes, set-points, faults, the safe state) land in ``/events`` on the file's time
base. Any exception closes the file "aborted: <why>" and is raised again.
"""

from __future__ import annotations

import logging
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from fbs.drivers.errors import DriverError, SampleGap
from fbs.drivers.rig import Rig

from .runfile import RunWriter

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
           ranges_V: Mapping[str, float] | float | None = None, block_s: float = 0.5,
           procedure: str | None = None, meta: Mapping[str, Any] | None = None) -> RecordResult:
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
                       procedure=procedure, meta=meta)
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
        writer.event(0.0, "start", f"recording {len(channels)} channels at {cfg.rate_hz:g} Hz, mode {mode}")
        pos = 0
        while pos < total:
            try:
                block = rig.adc.read(min(per, total - pos))
            except SampleGap as gap:
                stop = min(gap.stop, total)
                writer.append({c: np.full(stop - pos, np.nan) for c in channels})
                writer.event(gap.start / cfg.rate_hz, "gap", str(gap))
                result.gaps.append((gap.start, gap.stop, gap.reason))
                pos = stop
                continue
            writer.append({c: block[c] for c in channels})
            over = block.overrange.any(axis=0)
            for j in np.flatnonzero(over):
                k = int(block.overrange[:, j].argmax())
                writer.event((block.first_sample + k) / cfg.rate_hz, "overrange",
                             f"{channels[j]}: {int(block.overrange[:, j].sum())} samples at full scale")
            pos = block.stop_sample
            flush_events()
        rig.adc.stop()
        result.samples = pos
    except BaseException as exc:
        status = "aborted: " + ("interrupted" if isinstance(exc, KeyboardInterrupt) else f"{type(exc).__name__}: {exc}")
        raise
    finally:
        rig.unsubscribe(on_event)
        if rig.adc.streaming and rig.faults.fault is None:
            try:
                rig.adc.stop()
            except DriverError as exc:
                log.warning("stopping the ADC after an abort failed: %s", exc)
        try:
            flush_events()
        finally:
            writer.close(status)
        result.status = status
        result.samples = result.samples or writer.n
    return result
