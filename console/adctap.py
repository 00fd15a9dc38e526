"""An ``Adc`` that hands a copy of every block it delivers to the meter store.

Whoever reads the ADC (the console's idle meter stream, a recording's ``Acquisition`` or a
procedure run by ``run_procedure``) reads through this tap, so the meters stay live whatever
owns the stream, without a second stream and without reading the run file back. It is a
decorator around the rig's real driver: every call is forwarded unchanged.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from typing import overload

from console.meterdata import MeterStore
from drivers.adc import Adc, AdcBlock, AdcConfig, AdcIdentity, AdcStatus

log = logging.getLogger(__name__)


class TappedAdc(Adc):
    def __init__(self, inner: Adc, store: MeterStore) -> None:
        self.inner = inner
        self.store = store
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
