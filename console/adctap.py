"""An ``Adc`` that hands a copy of every block it delivers to the meter store.

Whoever reads the ADC (the console's idle meter stream, a recording's ``Acquisition`` or a
procedure run by ``run_procedure``) reads through this tap, so the meters stay live whatever
owns the stream, without a second stream and without reading the run file back. It is a
decorator around the rig's real driver: every call is forwarded unchanged.

A procedure's rig time passes through its recording, block by block; after each block the tap
calls ``after_block`` (the rig's owner, ``RigWorker``, polls the rig's state there while a
procedure runs on its thread). Whatever that hook or the meter store raise is logged, never
passed to the reader: the meters' or the poll's trouble must never cost a sample.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping
from typing import overload

from console.meterdata import MeterStore
from drivers.adc import Adc, AdcBlock, AdcConfig, AdcIdentity, AdcStatus
from drivers.errors import DriverError

log = logging.getLogger(__name__)


class TappedAdc(Adc):
    def __init__(self, inner: Adc, store: MeterStore, after_block: Callable[[], None] | None = None) -> None:
        self.inner = inner
        self.store = store
        self.after_block = after_block
        self.identity = inner.identity

    @overload
    def _tap(self, block: AdcBlock) -> AdcBlock: ...

    @overload
    def _tap(self, block: AdcBlock | None) -> AdcBlock | None: ...

    def _tap(self, block: AdcBlock | None) -> AdcBlock | None:
        if block is not None and len(block):
            try:
                self.store.push(block.channels, block.volts, block.rate_hz,
                                block.t0_s + block.stop_sample / block.rate_hz)
            except Exception:  # the meters' trouble must never cost a sample of the recording
                log.exception("meter store rejected a block")
            if self.after_block is not None:
                try:
                    self.after_block()
                except DriverError as exc:  # a fault: the reader meets it on its own next call
                    log.debug("polling after a block: %s", exc)
                except Exception:
                    log.exception("polling after a block failed")
        return block

    def identify(self) -> AdcIdentity:
        return self.inner.identify()

    def configure(self, channels: tuple[str, ...] | list[str], rate_hz: float,
                  ranges_V: Mapping[str, float] | float | None = None, frame_sets: int | None = None) -> AdcConfig:
        return self.inner.configure(channels, rate_hz, ranges_V, frame_sets)

    @property
    def config(self) -> AdcConfig | None:
        return self.inner.config

    @property
    def streaming(self) -> bool:
        return self.inner.streaming

    def start(self) -> float:
        return self.inner.start()

    def read(self, n: int, timeout_s: float | None = None) -> AdcBlock:
        return self._tap(self.inner.read(n, timeout_s))

    def read_available(self) -> AdcBlock | None:
        return self._tap(self.inner.read_available())

    def stop(self) -> AdcStatus:
        return self.inner.stop()

    def status(self) -> AdcStatus:
        return self.inner.status()

    def close(self) -> None:
        self.inner.close()

    def __getattr__(self, name: str):
        # driver-specific extras (a serial ADC's port, timeouts) stay reachable
        return getattr(self.inner, name)
