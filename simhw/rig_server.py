"""The loopback rig: the simulator behind real wires (a pty for the ADC, a virtual CAN bus).

``SimRigServer`` owns a ``Simulator`` and one physics thread that advances it block by
block. Every device emulation (``AdcDevice``, the CAN nodes) changes the physics only
through ``submit``, which runs at the next block boundary on the physics thread, so the
simulator is never touched by two threads.

Time: with ``realtime`` the simulation is paced to the wall clock and runs by itself, like
hardware. Otherwise time is *virtual*: the physics advances only as far as someone has asked
for it, by waiting (``SimClock.sleep``) or by reading ADC data (``SimClock.demand``), so a
procedure finishes as fast as the simulation can run, and a command sent while the host is
busy lands at a well-defined rig time.
"""

from __future__ import annotations

import logging
import math
import threading
import time
import uuid
from collections.abc import Callable, Collection
from dataclasses import dataclass, field

import numpy as np

from drivers.errors import DeviceLost, DeviceTimeout
from simhw.adc_device import AdcDevice
from simhw.can_nodes import CanNodeHost
from simhw.config import GYRO_CHANNELS, SimConfig
from simhw.simulator import Simulator
from simhw.virtual_clock import PacedClock, VirtualClock

log = logging.getLogger(__name__)

#: The relay driver's null detector: a channel counts as caged when its pickoff, averaged
#: over about a second, stays below this (V at the demodulator; ~170 urad at Kg ~6 mV/urad,
#: well inside the +-1 mrad linear range, and above the steady offset of XRD's
#: proportional-only caging loop, ~0.34 V).
CAGED_NULL_V = 1.0
NULL_AVERAGE_S = 1.0
_PICKOFF = {"X": "gyro_x", "Y": "gyro_y", "Z": "gyro_z", "XRD": "gyro_xrd"}


@dataclass(frozen=True)
class Snapshot:
    """What the node electronics can see of the rig, refreshed every block."""

    time_s: float = 0.0
    mode: int = 1
    spin: float = 0.0
    at_speed: bool = False
    caged: dict[str, bool] = field(default_factory=lambda: dict.fromkeys(GYRO_CHANNELS, False))


_COMPILED: set[float] = set()  # sample rates whose kernels this process has compiled or loaded


def _compile_kernels(cfg: SimConfig | None, rate_hz: float) -> None:
    """Compile (or load from numba's cache) the simulator's kernels before any device thread
    runs: a cold compile holds the GIL for seconds, and an ADC that cannot answer START for
    that long looks dead to the driver. A throwaway simulator runs a few samples."""
    if rate_hz in _COMPILED:
        return
    for _ in Simulator(cfg, rate_hz=rate_hz, seed=0, mode=3, spin=None).run(0.01, 0.01):
        pass
    _COMPILED.add(rate_hz)


class SimRigServer:
    def __init__(
        self,
        cfg: SimConfig | None = None,
        *,
        seed: int = 0,
        realtime: bool = False,
        speed: float = 1.0,
        warm: bool = False,
        rate_hz: float = 1000.0,
        max_block_s: float = 1.0,
        paced_block_s: float = 0.01,
        watchdog_s: float = 1.0,
        monotonic: Callable[[], float] = time.monotonic,
        can_channel: str | None = None,
        external_nodes: Collection[str] = (),
        can_interface: str = "virtual",
    ) -> None:
        self.seed = seed
        #: the devices' deadline clock (``drivers.runclock.RunningClock`` from the sim rig scheme)
        self.monotonic = monotonic
        self.paced = realtime
        self.max_block_s = max_block_s
        self.paced_block_s = paced_block_s
        self._wall0 = time.monotonic()
        _compile_kernels(cfg, rate_hz)
        clock = PacedClock(speed) if realtime else VirtualClock()
        self.sim = Simulator(
            cfg,
            rate_hz=rate_hz,
            seed=seed,
            mode=3 if warm else 1,
            spin=None if warm else 0.0,
            clock=clock,
        )
        self._cond = threading.Condition()
        #: (rig time due, fn, inline): due at the demand or the horizon when submitted (0: at
        #: once); an inline one (a set-point) may step inside a physics block
        self._pending: list[tuple[float, Callable[[Simulator], None], bool]] = []
        #: how far a host waits for the rig to run (virtual time: the physics runs to it)
        self._demand = 0.0
        #: the rig time a host's next command is for (``SimClock.at``): nobody waits for it
        self._horizon = 0.0
        self._time = self.sim.time_s
        self._null = {c: (0.0 if warm else 1.0) for c in GYRO_CHANNELS}
        self.snapshot = self._snap(None)
        self.error: BaseException | None = None
        self.stall_reason = ""
        self._stop = threading.Event()
        self.adc = AdcDevice(self)
        #: the CAN channel (python-can ``virtual``, this process only, unless ``can_interface``
        #: says otherwise: ``udp_multicast`` serves hosts in other processes, ``simhw.serve``);
        #: ``external_nodes`` are left to devices the caller puts on it
        self.can_channel = can_channel or f"fbs-sim-{uuid.uuid4().hex[:12]}"
        self.nodes = CanNodeHost(
            self,
            self.can_channel,
            interface=can_interface,
            watchdog_s=watchdog_s,
            monotonic=monotonic,
            external=external_nodes,
        )
        self.clock = SimClock(self)
        self._thread = threading.Thread(target=self._run, name="sim-physics", daemon=True)
        self._thread.start()

    @property
    def adc_port(self) -> str:
        return self.adc.port

    def wall(self) -> float:
        return time.monotonic() - self._wall0

    # ------------------------------------------------------------------ for the devices
    def submit(self, fn: Callable[[Simulator], None], *, inline: bool = False) -> None:
        """Run ``fn(sim)`` on the physics thread at the rig time last demanded or scheduled
        (``horizon``; virtual time), or before the next block (paced): a command lands at a
        rig time that does not depend on how far the physics thread happened to have got when
        it arrived. (A host's read that finds its samples already there returns before the
        physics has taken up its demand; "the next block" was then the one before or the one
        after it, by the host's load.) ``inline``: ``fn`` changes only the physics (a
        set-point), so it may step inside a block (``Simulator.advance``'s events) rather
        than end it; the ADC's own changes end a block."""
        with self._cond:
            self._pending.append((max(self._demand, self._horizon), fn, inline))
            self._cond.notify_all()

    def demand(self, t: float) -> None:
        """A host waits for the rig to run to ``t``: the physics runs to it."""
        with self._cond:
            if t > self._demand:
                self._demand = t
                self._cond.notify_all()

    def schedule(self, t: float) -> None:
        """A host's next command is for rig time ``t``; nobody waits for it, so the physics is
        not woken: a stream of set-points then runs as one block, not one block each."""
        with self._cond:
            self._horizon = max(self._horizon, t)

    def horizon(self) -> float:
        """The rig time a command submitted now lands at (virtual time)."""
        with self._cond:
            return max(self._demand, self._horizon)

    @property
    def time_s(self) -> float:
        return self._time

    def inject(self, device: str, fault: str, **kw) -> None:
        """Fault injection for tests: ``device`` is ``adc`` or a CAN node name."""
        if device == "adc":
            self.adc.inject(fault, **kw)
        else:
            self.nodes.inject(device, fault, **kw)

    def wait_time(self, t: float, stall_s: float = 10.0) -> None:
        """Block until rig time reaches ``t``; a clear error if it stops advancing."""
        with self._cond:
            last, since = self._time, self.monotonic()
            while self._time < t - 1e-9:
                if self.error is not None:
                    raise DeviceLost(f"the simulated rig stopped: {self.error!r}")
                if self._stop.is_set():
                    raise DeviceLost("the simulated rig was closed")
                self._cond.wait(0.05)
                if self._time != last:
                    last, since = self._time, self.monotonic()
                elif self.monotonic() - since > stall_s:
                    raise DeviceTimeout(
                        f"rig time stalled at {self._time:.3f} s while waiting for {t:.3f} s"
                        + (f": {self.stall_reason}" if self.stall_reason else "")
                    )

    # ------------------------------------------------------------------ physics thread
    def _run(self) -> None:
        sim = self.sim
        try:
            while not self._stop.is_set():
                with self._cond:
                    # due: at or before this sample (due times are in submission order: the
                    # demand never goes back)
                    k = 0
                    while k < len(self._pending) and self._samples_to(self._pending[k][0]) <= 0:
                        k += 1
                    todo, self._pending = self._pending[:k], self._pending[k:]
                    for _, fn, _ in todo:
                        fn(sim)
                    events: list[tuple[int, Callable[[Simulator], None]]] = []
                    if self.paced:
                        n = max(1, round(self.paced_block_s * sim.rate_hz))
                    else:
                        # the physics runs to the demand, and to any command but a set-point (a
                        # host may wait for its answer: an ADC's STOP after a stream ended early,
                        # the stream's set-points scheduled past the last read); no later
                        # command is due before a pending one, so running to it is safe
                        target = max(
                            [self._demand] + [due for due, _, inline in self._pending if not inline]
                        )
                        n = min(
                            self._samples_to(target),
                            max(1, round(self.max_block_s * sim.rate_hz)),
                        )
                        # set-points due inside the block step there; any other command ends
                        # the block where it is due. Every command due before the demand is
                        # here: one submitted later is due at the demand or after it.
                        for due, fn, inline in self._pending:
                            at = self._samples_to(due)
                            if at >= n:
                                break
                            if not inline:
                                n = at  # an inline one due with it waits for the next block
                                events = [e for e in events if e[0] < n]
                                break
                            events.append((at, fn))
                        del self._pending[: len(events)]
                        if n <= 0:
                            if not todo:
                                self._cond.wait(0.05)
                            continue
                block = sim.advance(n, events, setpoints=True)  # inline: set-points only
                self.snapshot = self._snap(block)
                self.stall_reason = "the ADC stream is not being read (device FIFO full)"
                self.adc.on_block(block)
                self.stall_reason = ""
                with self._cond:
                    self._time = sim.time_s
                    self._cond.notify_all()
        except BaseException as exc:  # the rig dies loudly: devices go silent, waiters are told
            log.exception("simulated rig: physics thread failed")
            self.error = exc
            self.adc.disconnect()
            for node in self.nodes.nodes.values():
                node.connected = False
            with self._cond:
                self._cond.notify_all()

    def _samples_to(self, t: float) -> int:
        """Samples from the physics' time to the first sample boundary at or after ``t``."""
        sim = self.sim
        return math.ceil((t - sim.time_s) * sim.rate_hz - 1e-6)

    def _snap(self, block) -> Snapshot:
        sim = self.sim
        if block is not None and len(block):
            alpha = min(1.0, len(block) / sim.rate_hz / NULL_AVERAGE_S)
            for c, name in _PICKOFF.items():
                self._null[c] += alpha * (float(np.mean(np.abs(block[name]))) - self._null[c])
        ready = sim.gyros_at_speed
        caged = {
            c: bool(
                ready
                and sim.mode in (3, 4, 5)
                and not sim.relays.caging_inhibit[i]
                and self._null[c] < CAGED_NULL_V
            )
            for i, c in enumerate(GYRO_CHANNELS)
        }
        return Snapshot(sim.time_s, sim.mode, sim.spin, ready, caged)

    def stop(self) -> None:
        self._stop.set()
        with self._cond:
            self._cond.notify_all()
        self.adc.close()
        self._thread.join(timeout=5.0)
        self.nodes.close()


class SimClock:
    """The simulated rig's clock (``drivers.clock.RigClock``): rig time is simulated time."""

    def __init__(self, server: SimRigServer) -> None:
        self.server = server
        self.virtual = not server.paced

    def now(self) -> float:
        return self.server.time_s

    def demand(self, t: float) -> None:
        if self.virtual:
            self.server.demand(t)

    def horizon(self) -> float:
        return self.server.horizon() if self.virtual else self.now()

    def at(self, t: float) -> None:
        if self.virtual:
            self.server.schedule(t)
        else:
            self.server.wait_time(t)

    def unix_time(self, t: float) -> float | None:
        return self.server.sim.clock.unix_time(t)

    def sleep(self, seconds: float) -> None:
        if not seconds > 0:
            return
        target = self.now() + seconds
        self.demand(target)
        self.server.wait_time(target)
