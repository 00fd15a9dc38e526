"""An ``Adc`` that hands a copy of every block it delivers to the meter store.

Whoever reads the ADC (the console's idle meter stream, a recording's ``Acquisition`` or a
procedure run by ``run_procedure``) reads through this tap, so the meters stay live whatever
owns the stream, without a second stream and without reading the run file back. It is a
decorator (``drivers.adc.AdcDecorator``) around the rig's driver: every call is forwarded unchanged.

A procedure's rig time passes through its recording, block by block; after each block the tap
calls ``after_block`` (the rig's owner, ``RigWorker``, polls the rig's state there while a
procedure runs on its thread). Whatever that hook or the meter store raise is logged, never
passed to the reader: the meters' or the poll's trouble must never cost a sample.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

from console.meterdata import MeterStore
from drivers.adc import Adc, AdcBlock, AdcDecorator
from drivers.errors import DriverError

log = logging.getLogger(__name__)


class TappedAdc(AdcDecorator):
    def __init__(
        self, inner: Adc, store: MeterStore, after_block: Callable[[], None] | None = None
    ) -> None:
        super().__init__(inner)
        self.store = store
        self.after_block = after_block

    def _deliver(self, block: AdcBlock) -> None:
        try:
            self.store.push(
                block.channels,
                block.volts,
                block.rate_hz,
                block.t0_s + block.stop_sample / block.rate_hz,
            )
        except Exception:  # the meters' trouble must never cost a sample of the recording
            log.exception("meter store rejected a block")
        if self.after_block is not None:
            try:
                self.after_block()
            except DriverError as exc:  # a fault: the reader meets it on its own next call
                log.debug("polling after a block: %s", exc)
            except Exception:
                log.exception("polling after a block failed")
