"""The ADC: what a driver of it offers, whatever the wire (DESIGN.md sections 2 and 5)."""

from __future__ import annotations

import abc
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class AdcIdentity:
    vendor: str
    model: str
    serial: str
    firmware: str
    bits: int
    max_aggregate_rate_hz: float  # sample sets/s x channels the device can stream
    ranges_V: tuple[float, ...]  # selectable full-scale ranges (+-V)
    channels: tuple[str, ...]  # input names, DESIGN.md section 5


@dataclass(frozen=True)
class AdcConfig:
    channels: tuple[str, ...]
    rate_hz: float
    ranges_V: dict[str, float]
    frame_sets: int  # sample sets per frame on the wire


@dataclass(frozen=True)
class AdcStatus:
    streaming: bool
    samples: int  # sample sets sent since START (device count)
    frames: int
    overruns: int  # device FIFO overflows since START


@dataclass
class AdcBlock:
    """Contiguous sample sets ``first_sample ..`` of a stream; volts as converted by the ADC.

    ``volts`` is indexed [sample, channel] but laid out channel by channel (``volts.T`` is
    C-contiguous): each channel's samples are contiguous, as a run file stores them.
    ``overrange`` marks samples at an end code (at or beyond full scale): clipped, never wrapped.
    """

    first_sample: int
    rate_hz: float
    t0_s: float  # rig time of the stream's sample 0
    channels: tuple[str, ...]
    volts: np.ndarray  # (n, n_channels) float64, channel-major in memory
    overrange: np.ndarray = field(repr=False)  # (n, n_channels) bool

    def __len__(self) -> int:
        return len(self.volts)

    def __getitem__(self, channel: str) -> np.ndarray:
        return self.volts[:, self.channels.index(channel)]

    @property
    def stop_sample(self) -> int:
        return self.first_sample + len(self.volts)

    @property
    def time_s(self) -> np.ndarray:
        """Rig time of each sample set."""
        return self.t0_s + (self.first_sample + np.arange(len(self.volts))) / self.rate_hz


class Adc(abc.ABC):
    """Configure, start, read, stop. ``read`` raises ``SampleGap`` where samples were lost."""

    identity: AdcIdentity  # what ``identify`` answered when the driver opened the device

    @abc.abstractmethod
    def identify(self) -> AdcIdentity: ...

    @abc.abstractmethod
    def configure(
        self,
        channels: tuple[str, ...] | list[str],
        rate_hz: float,
        ranges_V: Mapping[str, float] | float | None = None,
        frame_sets: int | None = None,
    ) -> AdcConfig: ...

    @property
    @abc.abstractmethod
    def config(self) -> AdcConfig | None: ...

    @property
    @abc.abstractmethod
    def streaming(self) -> bool: ...

    @abc.abstractmethod
    def start(self) -> float:
        """Start streaming; returns the rig time of sample 0."""

    @abc.abstractmethod
    def read(self, n: int, timeout_s: float | None = None) -> AdcBlock:
        """The next ``n`` sample sets (fewer only if a gap follows them; the next call raises it)."""

    @abc.abstractmethod
    def read_available(self) -> AdcBlock | None:
        """Whatever has arrived, without waiting (None if nothing)."""

    @abc.abstractmethod
    def stop(self) -> AdcStatus: ...

    @abc.abstractmethod
    def status(self) -> AdcStatus: ...

    @abc.abstractmethod
    def close(self) -> None: ...


class AdcDecorator(Adc):
    """An ``Adc`` around another, every call forwarded unchanged, each block it delivers shown to
    ``_deliver`` first (the rig's mode supervision, the console's meters). What ``_deliver``
    raises reaches the reader: a decorator that must never cost a sample catches its own."""

    def __init__(self, inner: Adc) -> None:
        self.inner = (
            inner  # its ``identity`` and every other attribute read through (``__getattr__``)
        )

    def _deliver(self, block: AdcBlock) -> None:
        """See a block on its way to the reader (nothing here)."""

    def identify(self) -> AdcIdentity:
        return self.inner.identify()

    def configure(
        self,
        channels: tuple[str, ...] | list[str],
        rate_hz: float,
        ranges_V: Mapping[str, float] | float | None = None,
        frame_sets: int | None = None,
    ) -> AdcConfig:
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
        block = self.inner.read(n, timeout_s)
        if len(block):
            self._deliver(block)
        return block

    def read_available(self) -> AdcBlock | None:
        block = self.inner.read_available()
        if block is not None and len(block):
            self._deliver(block)
        return block

    def stop(self) -> AdcStatus:
        return self.inner.stop()

    def status(self) -> AdcStatus:
        return self.inner.status()

    def close(self) -> None:
        self.inner.close()

    def __getattr__(self, name: str):
        # driver-specific extras (a serial ADC's port, timeouts) stay reachable
        return getattr(self.inner, name)

    def __setattr__(self, name: str, value: object) -> None:
        # ... and settable: a driver's setting (``stall_timeout_s``) set on the decorator is the driver's
        inner = self.__dict__.get("inner")
        if (
            inner is not None
            and name not in self.__dict__
            and not hasattr(type(self), name)
            and hasattr(inner, name)
        ):
            setattr(inner, name, value)
        else:
            object.__setattr__(self, name, value)
