"""The ADC over a serial line (pyserial): the protocol of ``adc_protocol`` / docs/protocol.md 1.

A reader thread drains the port, decodes frames and replies, checks every frame's CRC,
sequence counter and first-sample index, and queues the samples. Lost or corrupted frames
become ``SampleGap`` items at their exact sample positions, so ``read`` raises them in stream
order and never splices across them. Replies go to the command in flight.

On a virtual (simulated) clock a full buffer holds the reader back, and with it the
simulation; on hardware it is a host overrun, reported as a gap like any other loss.

Connecting resynchronises first (docs/protocol.md 1.8): an ADC that an earlier host left
streaming (the process was killed) sends the rest of a frame cut anywhere, the frames made
since, and the replies nobody read. The host sends an empty line and ``STOP`` and discards
everything up to ``OK STOP``, then ``STAT?`` and everything up to ``OK STAT``, before ``IDN?``.
"""

from __future__ import annotations

import logging
import math
import queue
import threading
import time
from collections import deque
from collections.abc import Callable, Mapping

import numpy as np
import serial

from drivers.adc import Adc, AdcBlock, AdcConfig, AdcIdentity, AdcStatus
from drivers.adc_protocol import (
    CODE_MAX,
    CODE_MIN,
    FLAG_OVERRUN,
    MAX_CHANNELS,
    MAX_SETS,
    Frame,
    Reply,
    StreamDecoder,
    encode_command,
    encode_resync,
)
from drivers.clock import RigClock, WallClock
from drivers.errors import (
    DeviceLost,
    DeviceTimeout,
    DriverError,
    InterlockError,
    ProtocolError,
    RigBusy,
    SampleGap,
    SetpointRangeError,
)
from drivers.faults import FaultLatch

log = logging.getLogger(__name__)

#: Default frame length: about 10 ms of samples; at most a second, so the stall check holds.
FRAME_SECONDS = 0.01
MAX_FRAME_SECONDS = 1.0
#: No byte for this long while a frame is incomplete: the frame will not be completed (its
#: length field was corrupted). Kept well inside the reply deadline the held-back reply has.
QUIET_S = 0.25
#: Resynchronisation at connect (docs/protocol.md 1.8): the most the host discards while it
#: waits for ``OK STOP`` (16 x the reference FIFO, a few seconds of the fastest stream), and
#: the most time it gives the device in all (5 x the default reply timeout; a clean connect
#: takes milliseconds). Besides, as for any reply, the device may not go silent for the reply
#: timeout, counted from the later of the send and the last byte received, so a slow host or
#: a long drain does not count against the device.
RESYNC_BYTES = 16 << 20
RESYNC_TIMEOUT_S = 10.0


def _count(n: int, what: str) -> str:
    return f"{n} {what}" + ("" if n == 1 else "s")


class _Resync:
    """What the reader discards while the host resynchronises at connect (docs/protocol.md 1.8).

    ``steps`` are the ``OK`` keywords that end each step, in order; the reader hands each of
    those replies to the host and discards every other unit until the last one has come."""

    HEAD = 48  # bytes of the start of the line kept for the error message

    def __init__(self, steps: tuple[str, ...]) -> None:
        self.steps = list(steps)
        self.nbytes = 0
        self.head = bytearray()
        self.frames = 0
        self.replies = 0
        self.last_reply = ""
        self.stale = 0  # replies other than ERR SYNTAX (the host's own empty line gets that)
        self.bad = 0
        self.first_bad = ""

    def received(self, data: bytes) -> None:
        self.nbytes += len(data)
        if len(self.head) < self.HEAD:
            self.head += data[: self.HEAD - len(self.head)]

    def discard(self, item: Frame | Reply | ProtocolError) -> None:
        if isinstance(item, Frame):
            self.frames += item.frames
        elif isinstance(item, Reply):
            self.replies += 1
            self.last_reply = f"{'OK' if item.ok else 'ERR'} {item.verb} {item.text}".strip()[:80]
            if item.ok or item.verb != "SYNTAX":
                self.stale += 1
        else:
            self.bad += 1
            self.first_bad = self.first_bad or str(item)

    def summary(self) -> str:
        parts = [
            _count(self.frames, "frame"),
            _count(self.replies, "other reply line")
            + (f" (the last {self.last_reply!r})" if self.replies else ""),
            _count(self.bad, "undecodable unit")
            + (f" (the first: {self.first_bad})" if self.bad else ""),
        ]
        return (
            f"{_count(self.nbytes, 'byte')}: {', '.join(parts)}; they began "
            f"{bytes(self.head)!r}" + (" ..." if self.nbytes > len(self.head) else "")
        )


def _err_from_reply(reply: Reply, what: str) -> DriverError:
    text = f"the ADC refused {what}: {reply.verb} {reply.text}"
    if reply.verb == "RANGE":
        return SetpointRangeError(text)
    if reply.verb in ("BUSY", "STATE"):
        return InterlockError(text)
    if reply.verb in ("SYNTAX", "UNKNOWN"):
        return ProtocolError(text + " (host and device disagree on the protocol)")
    return DriverError(text)


#: a command's reply deadline, s (from the later of the send and the last byte received)
ADC_REPLY_TIMEOUT_S = 2.0
#: silence while streaming that is a stall, s
ADC_STALL_TIMEOUT_S = 3.0


class SerialAdc(Adc):
    """Driver of the FBS ADC on a serial port (a USB CDC device, or the simulator's pty)."""

    def __init__(
        self,
        port: str,
        *,
        clock: RigClock | None = None,
        faults: FaultLatch | None = None,
        baudrate: int = 2_000_000,
        reply_timeout_s: float = ADC_REPLY_TIMEOUT_S,
        stall_timeout_s: float = ADC_STALL_TIMEOUT_S,
        buffer_s: float = 120.0,
        resync_bytes: int = RESYNC_BYTES,
        resync_timeout_s: float = RESYNC_TIMEOUT_S,
        quiet_s: float = QUIET_S,
        monotonic: Callable[[], float] = time.monotonic,
    ) -> None:
        self.port = port
        #: the clock of every deadline here: the wall's, or one that leaves out the host's pauses
        #: (``drivers.runclock``) for a device that runs in this process
        self._mono = monotonic
        self.clock = clock or WallClock()
        self.faults = faults or FaultLatch()
        self.reply_timeout_s = reply_timeout_s
        self.resync_bytes = resync_bytes
        self.resync_timeout_s = resync_timeout_s
        self.stall_timeout_s = stall_timeout_s
        self.quiet_s = quiet_s
        self.buffer_s = buffer_s
        try:
            # exclusive (flock): a second host's open fails here, before it sends a byte
            self.ser = serial.Serial(
                port, baudrate=baudrate, timeout=0.05, write_timeout=reply_timeout_s, exclusive=True
            )
        except serial.SerialException as exc:
            if "exclusively lock" in str(exc):
                raise RigBusy(
                    f"the ADC's serial port {port} is held by another program ({exc}); this command "
                    f"sent nothing to it. Close the other session, then try again"
                ) from exc
            raise DeviceLost(
                f"cannot open the ADC's serial port {port}: {exc}; check the cable, "
                f"the device path and that no other program holds the port"
            ) from exc
        except (OSError, ValueError) as exc:
            raise DeviceLost(
                f"cannot open the ADC's serial port {port}: {exc}; check the cable, "
                f"the device path and that no other program holds the port"
            ) from exc
        self._decoder = StreamDecoder(merge_runs=True)  # a run of frames read as one
        self._replies: queue.Queue = queue.Queue()
        self._cmd_lock = threading.Lock()
        self._cond = threading.Condition()
        self._items: deque = deque()  # (first_sample, codes) or SampleGap / ProtocolError
        self._buffered = 0  # sample sets held in _items
        self._capacity = 0
        self._rx_streaming = False  # between the START and STOP replies, as the reader sees it
        self._next_sample = 0
        self._next_seq = 0
        self._bad_data: str | None = None  # decode error since the last good frame
        self._read_pos = 0
        self._t0 = 0.0
        self._config: AdcConfig | None = None
        self._last_rx = self._mono()
        self._closed = False
        self._stopping = False  # STOP sent: a full buffer may no longer hold the reader
        # From the first byte read until the device's OK STAT, everything is discarded (1.8).
        self._sync: _Resync | None = _Resync(("STOP", "STAT"))
        self._thread = threading.Thread(target=self._reader, name="adc-reader", daemon=True)
        self._thread.start()
        try:
            self._resync()
            self.identity = self.identify()
        except DriverError:
            self.close()
            raise

    # ------------------------------------------------------------------ reader thread
    def _reader(self) -> None:
        while not self._closed:
            try:
                waiting = self.ser.in_waiting
                data = self.ser.read(waiting if waiting > 0 else 1)
            except (serial.SerialException, OSError, TypeError, AttributeError) as exc:
                if not self._closed:
                    self._lost(
                        DeviceLost(
                            f"ADC on {self.port}: the serial device went away ({exc}); "
                            f"check the cable and power, then reopen the rig"
                        )
                    )
                return
            if not data:
                # A frame cut short (corrupted length field) would hold back what follows,
                # such as the STOP reply, for ever: after a quiet spell, give it up.
                if self._decoder.pending() and self._mono() - self._last_rx > self.quiet_s:
                    self._decoder.quiet()
                    self._dispatch()
                continue
            self._last_rx = self._mono()
            sync = self._sync
            if sync is not None:
                sync.received(data)
            self._decoder.feed(data)
            self._dispatch()

    def _dispatch(self) -> None:
        for item in self._decoder.items():
            sync = self._sync
            if sync is not None:
                self._on_resync_item(sync, item)
            elif isinstance(item, Frame):
                self._on_frame(item)
            elif isinstance(item, Reply):
                self._on_reply(item)
            else:
                self._on_bad_bytes(item)

    def _on_resync_item(self, sync: _Resync, item: Frame | Reply | ProtocolError) -> None:
        """While resynchronising: hand over the reply that ends a step, discard the rest."""
        if isinstance(item, Reply) and item.ok and item.verb == sync.steps[0]:
            sync.steps.pop(0)
            if not sync.steps:
                self._sync = None  # in sync: what follows is the replies to the host's commands
            self._replies.put(item)
        else:
            sync.discard(item)

    def _on_reply(self, reply: Reply) -> None:
        if reply.ok and reply.verb == "START":
            with self._cond:
                self._items.clear()
                self._buffered = 0
                self._next_sample = self._next_seq = self._read_pos = 0
                self._bad_data = None
                self._rx_streaming = True
        elif reply.ok and reply.verb == "STOP":
            try:
                sent = int(reply.fields.get("samples", self._next_sample))
            except ValueError:
                with self._cond:
                    self._rx_streaming = False
                    self._cond.notify_all()
                self._replies.put(
                    ProtocolError(f"STOP reply {reply.text!r}: samples= is not an integer")
                )
                return
            with self._cond:
                if self._rx_streaming and sent > self._next_sample:
                    self._push(
                        SampleGap(
                            self._next_sample, sent, self._bad_data or "frames lost before STOP"
                        )
                    )
                    self._next_sample = sent
                self._rx_streaming = False
                self._cond.notify_all()
        self._replies.put(reply)

    def _on_bad_bytes(self, err: ProtocolError) -> None:
        log.warning("ADC on %s: %s", self.port, err)
        if self._rx_streaming:
            self._bad_data = self._bad_data or str(err)
        else:
            self._replies.put(err)

    def _on_frame(self, frame: Frame) -> None:
        with self._cond:
            if not self._rx_streaming:
                log.warning(
                    "ADC on %s: frame seq %d outside a stream, ignored", self.port, frame.seq
                )
                return
            first = frame.first_sample  # the decoder has checked the channel count
            if first < self._next_sample:
                fault = ProtocolError(
                    f"ADC frame seq {frame.seq} starts at sample {first}, before sample "
                    f"{self._next_sample} already received; the device's counters are "
                    f"inconsistent"
                )
                self._push(fault)
                self._report_unlocked(fault, stream_lost=False)
                return
            if first == self._next_sample and frame.seq != self._next_seq:
                log.warning(
                    "ADC on %s: frame seq %d, expected %d, with contiguous samples",
                    self.port,
                    frame.seq,
                    self._next_seq,
                )
            if first > self._next_sample:
                if self._bad_data:
                    reason = f"corrupted frame(s): {self._bad_data}"
                elif frame.seq != self._next_seq:
                    reason = (
                        f"frame(s) seq {self._next_seq}..{(frame.seq - 1) & 0xFFFFFFFF} missing "
                        f"(sequence counter)"
                    )
                else:
                    reason = "sample index jumped (frame counter consistent)"
                if frame.flags & FLAG_OVERRUN:
                    reason += "; the device reports a FIFO overrun"
                self._push(SampleGap(self._next_sample, first, reason))
            self._bad_data = None
            self._push_samples(first, frame.codes, frame.n_sets // frame.frames)
            self._next_sample = first + frame.n_sets
            self._next_seq = (frame.seq + frame.frames) & 0xFFFFFFFF

    def _push(self, item: SampleGap | DriverError) -> None:
        """Queue a gap or a fault (caller holds _cond): they take no room in the buffer."""
        self._items.append(item)
        self._cond.notify_all()

    def _push_samples(self, first: int, codes: np.ndarray, unit: int) -> None:
        """Queue samples from ``first`` (caller holds _cond) in whole ``unit`` sets, a frame's: a
        run of merged frames is kept or dropped frame by frame, as the frames one by one would
        be. A full buffer: wait (virtual clock) or overrun."""
        while len(codes):
            room = max(0, self._capacity - self._buffered) // unit * unit
            fit = len(codes) if self._closed else min(len(codes), room)
            if fit:
                self._buffered += fit
                self._items.append((first, codes[:fit]))
                self._cond.notify_all()
                first, codes = first + fit, codes[fit:]
            elif not self.clock.virtual or self._stopping:
                n = len(codes)
                log.error("ADC host buffer full: samples %d..%d dropped", first, first + n - 1)
                self._merge_gap(
                    SampleGap(
                        first,
                        first + n,
                        "host buffer overrun: the application did not read the stream in time",
                    )
                )
                return
            else:
                self._cond.wait(0.05)

    def _merge_gap(self, gap: SampleGap) -> None:
        last = self._items[-1] if self._items else None
        if isinstance(last, SampleGap) and last.stop == gap.start and last.reason == gap.reason:
            self._items[-1] = SampleGap(last.start, gap.stop, gap.reason)
        else:
            self._items.append(gap)
        self._cond.notify_all()

    def _lost(self, fault: DriverError) -> None:
        with self._cond:
            self._rx_streaming = False
            self._cond.notify_all()
        self.faults.report(fault)

    # ------------------------------------------------------------------ connecting
    def _resync(self) -> None:
        """Bring the byte stream to a known point before the first command (docs/protocol.md 1.8).

        An ADC that an earlier host left streaming sends the rest of a frame cut anywhere, the
        frames made since and the replies nobody read; a dead host may also have left half a
        command line in the device. So: an empty line (ends that line; answered ERR SYNTAX) and
        STOP, and everything up to OK STOP is discarded; then STAT?, and everything up to OK
        STAT is discarded (the first OK STOP may have been a dead host's own). Bounded by
        ``resync_bytes`` and ``resync_timeout_s``, and the device may not go silent for the
        reply timeout, measured, as for any reply, from the later of the send and the last byte.
        """
        sync = self._sync
        assert sync is not None
        t_start = self._mono()
        with self._cmd_lock:
            self._send(encode_resync(), "STOP")
            self._await_resync(sync, "STOP", t_start)
            self._send(encode_command("STAT?"), "STAT?")
            stat = self._await_resync(sync, "STAT", t_start)
        if stat.fields.get("state") == "streaming":
            fault = ProtocolError(
                f"ADC on {self.port}: still streaming after STOP at connect ('OK STAT {stat.text}'); "
                f"power-cycle the ADC, then reopen the rig"
            )
            self.faults.report(fault)
            raise fault
        if sync.frames or sync.bad or sync.stale:
            log.warning(
                "ADC on %s had output left when opened (an earlier session ended without STOP?): stopped "
                "it and discarded %s",
                self.port,
                sync.summary(),
            )
        else:
            log.debug("ADC on %s: in sync after %s", self.port, sync.summary())

    def _await_resync(self, sync: _Resync, keyword: str, t_start: float) -> Reply:
        sent = self._mono()
        while True:
            self.faults.check()  # the port went away under the reader
            try:
                reply: Reply = self._replies.get(timeout=0.05)
                return reply
            except queue.Empty:
                pass
            now = self._mono()
            if now - max(self._last_rx, sent) > self.reply_timeout_s:
                why = f"then nothing for {self.reply_timeout_s:g} s"
            elif sync.nbytes > self.resync_bytes:
                why = f"not within {_count(self.resync_bytes, 'byte')}"
            elif now - t_start > self.resync_timeout_s:
                why = f"not within {self.resync_timeout_s:g} s"
            else:
                continue
            asked = "STOP" if keyword == "STOP" else "STAT? (after STOP)"
            advice = (
                f"check that {self.port} is the FBS ADC (not another device), that it is powered and its "
                f"baud rate is {self.ser.baudrate}; power-cycle the ADC, then reopen the rig"
            )
            fault: DriverError
            if not sync.nbytes:
                fault = DeviceTimeout(
                    f"ADC on {self.port}: no reply to {asked} at connect within "
                    f"{self.reply_timeout_s:g} s: the device sent nothing at all; {advice}"
                )
            else:
                fault = ProtocolError(
                    f"ADC on {self.port}: cannot resynchronise at connect: sent {asked} and read "
                    f"{sync.summary()}, but no 'OK {keyword}' reply ({why}); {advice}"
                )
            self.faults.report(fault)
            raise fault

    # ------------------------------------------------------------------ commands
    def _send(self, data: bytes, what: str) -> None:
        try:
            self.ser.write(data)
        except (serial.SerialException, OSError) as exc:
            fault = DeviceLost(
                f"ADC on {self.port}: cannot send {what!r} ({exc}); the device went away"
            )
            self._lost(fault)
            raise fault from exc

    def _await_reply(self) -> Reply | ProtocolError | None:
        """The next reply, or None after ``reply_timeout_s`` on this driver's deadline clock."""
        deadline = self._mono() + self.reply_timeout_s
        while True:
            try:
                reply: Reply | ProtocolError = self._replies.get(timeout=0.05)
                return reply
            except queue.Empty:
                if self._mono() > deadline:
                    return None

    def _drop_stale_replies(self) -> None:
        """Replies nobody waits for any more (to a command that timed out): not this one's."""
        while not self._replies.empty():
            log.warning("ADC on %s: stale reply dropped: %s", self.port, self._replies.get_nowait())

    def _command(self, verb: str, *args: object, what: str | None = None) -> Reply:
        self.faults.check()
        if self._closed:
            raise DeviceLost(f"ADC on {self.port} is closed")
        what = what or " ".join([verb, *map(str, args)])
        with self._cmd_lock:
            self._drop_stale_replies()
            self._send(encode_command(verb, *args), what)
            reply = self._await_reply()
            if reply is None:
                fault: DriverError = DeviceTimeout(
                    f"ADC on {self.port}: no reply to {what!r} within {self.reply_timeout_s:g} s"
                    + (f" (last bad data: {self._bad_data})" if self._bad_data else "")
                )
                self.faults.report(fault)
                raise fault from None
        if isinstance(reply, ProtocolError):
            fault = ProtocolError(f"ADC on {self.port}: bad reply to {what!r}: {reply}")
            self.faults.report(fault)
            raise fault
        keyword = verb.rstrip("?")
        if reply.ok and reply.verb != keyword:
            fault = ProtocolError(
                f"ADC on {self.port}: unexpected reply 'OK {reply.verb} {reply.text}' to {what!r}"
            )
            self.faults.report(fault)
            raise fault
        if not reply.ok:
            err = _err_from_reply(reply, what)
            if not isinstance(err, (SetpointRangeError, InterlockError)):
                self.faults.report(err)  # the device is not the one the host speaks to
            raise err
        return reply

    def identify(self) -> AdcIdentity:
        r = self._command("IDN?")
        ch = self._command("CHAN?")
        try:
            return AdcIdentity(
                vendor=r.field("vendor"),
                model=r.field("model"),
                serial=r.field("serial"),
                firmware=r.field("fw"),
                bits=int(r.field("bits")),
                max_aggregate_rate_hz=float(r.field("max_rate_hz")),
                ranges_V=tuple(float(v) for v in r.field("ranges").split(",")),
                channels=tuple(ch.words[0].split(",")) if ch.words else (),
            )
        except ValueError as exc:
            raise ProtocolError(
                f"ADC on {self.port}: identity reply {r.text!r} is malformed: {exc}"
            ) from exc

    @property
    def config(self) -> AdcConfig | None:
        return self._config

    @property
    def streaming(self) -> bool:
        return self._rx_streaming

    def configure(
        self,
        channels: tuple[str, ...] | list[str],
        rate_hz: float,
        ranges_V: Mapping[str, float] | float | None = None,
        frame_sets: int | None = None,
    ) -> AdcConfig:
        ident = self.identity
        channels = tuple(channels)
        # Everything is checked before the first byte goes out.
        if self._rx_streaming:
            raise InterlockError("the ADC is streaming; stop it before reconfiguring")
        if not channels:
            raise SetpointRangeError("no ADC channels chosen", value=channels, limit=ident.channels)
        if len(channels) > MAX_CHANNELS:
            raise SetpointRangeError(
                f"{len(channels)} channels requested; a frame carries at most {MAX_CHANNELS}",
                value=len(channels),
                limit=MAX_CHANNELS,
            )
        for c in channels:
            if c not in ident.channels:
                raise SetpointRangeError(
                    f"ADC channel {c!r} does not exist (channels: {', '.join(ident.channels)})",
                    value=c,
                    limit=ident.channels,
                )
        dup = {c for c in channels if channels.count(c) > 1}
        if dup:
            raise SetpointRangeError(
                f"ADC channel(s) {', '.join(sorted(dup))} chosen twice", value=channels
            )
        try:
            rate = float(rate_hz)
        except (TypeError, ValueError):
            raise SetpointRangeError(
                f"ADC sample rate {rate_hz!r} is not a number", value=rate_hz
            ) from None
        limit = ident.max_aggregate_rate_hz / len(channels)
        if not (math.isfinite(rate) and 0 < rate <= limit):
            raise SetpointRangeError(
                f"ADC sample rate {rate_hz!r} Hz is outside 0 < rate <= {limit:g} Hz "
                f"({ident.max_aggregate_rate_hz:g} samples/s shared by {len(channels)} channels)",
                value=rate_hz,
                limit=limit,
            )
        if ranges_V is None:
            ranges_V = max(ident.ranges_V)
        ranges = (
            dict(ranges_V) if isinstance(ranges_V, Mapping) else dict.fromkeys(channels, ranges_V)
        )
        for c, rng in ranges.items():
            if c not in channels:
                raise SetpointRangeError(
                    f"range given for {c!r}, which is not among the chosen channels",
                    value=c,
                    limit=channels,
                )
            if rng not in ident.ranges_V:
                raise SetpointRangeError(
                    f"ADC range {rng!r} V for {c} is not available (ranges: "
                    f"{', '.join(f'{v:g}' for v in ident.ranges_V)} V)",
                    value=rng,
                    limit=ident.ranges_V,
                )
        for c in channels:
            ranges.setdefault(c, max(ident.ranges_V))
        if frame_sets is None:
            frame_sets = int(min(MAX_SETS, max(1, round(rate * FRAME_SECONDS))))
        max_sets = int(min(MAX_SETS, max(1, rate * MAX_FRAME_SECONDS)))
        if not (isinstance(frame_sets, int) and 1 <= frame_sets <= max_sets):
            raise SetpointRangeError(
                f"frame length {frame_sets!r} sample sets is outside 1..{max_sets} (at most "
                f"{MAX_SETS} sets and {MAX_FRAME_SECONDS:g} s per frame)",
                value=frame_sets,
                limit=max_sets,
            )
        self._config = None  # from the first byte on, until the device has confirmed every setting
        r = self._command("CONF", "CHAN", ",".join(channels))
        self._expect(r, ["CHAN", ",".join(channels)])
        rate = float(f"{rate:.9g}")  # as it goes on the wire
        r = self._command("CONF", "RATE", f"{rate:.9g}")
        try:
            got_rate = float(r.words[1])
        except (IndexError, ValueError):
            got_rate = float("nan")
        if not got_rate == rate:
            # A device that cannot make a rate exactly must refuse it (ERR RANGE), not change it.
            fault = ProtocolError(
                f"ADC on {self.port}: rate echo {r.text!r} does not match the requested {rate:.9g} Hz"
            )
            self.faults.report(fault)
            raise fault
        for c in channels:
            self._expect(
                self._command("CONF", "RANGE", c, f"{ranges[c]:g}"), ["RANGE", c, f"{ranges[c]:g}"]
            )
        self._expect(self._command("CONF", "FRAME", frame_sets), ["FRAME", str(frame_sets)])
        self._scale = np.array([ranges[c] / 32768.0 for c in channels])
        self._decoder.expect_channels = len(channels)
        self._decoder.max_sets = frame_sets
        self._config = AdcConfig(channels, rate, ranges, frame_sets)
        return self._config

    def _expect(self, reply: Reply, words: list[str]) -> None:
        if list(reply.words[: len(words)]) != words:
            fault = ProtocolError(
                f"ADC on {self.port}: configuration echo 'OK {reply.verb} {reply.text}' does not "
                f"match the request {' '.join(words)!r}"
            )
            self.faults.report(fault)
            raise fault

    def start(self) -> float:
        cfg = self._config
        if cfg is None:
            raise InterlockError("configure the ADC (channels, rate, ranges) before starting it")
        if self._rx_streaming:
            raise InterlockError("the ADC is already streaming")
        with self._cond:
            self._capacity = max(int(self.buffer_s * cfg.rate_hz), 4 * cfg.frame_sets)
        self._command("START")
        self._t0 = self.clock.now()
        self._last_rx = self._mono()
        return self._t0

    def stop(self) -> AdcStatus:
        self._stopping = True
        try:
            r = self._command("STOP")
        finally:
            self._stopping = False
        return self._status_from(r, streaming=False)

    def status(self) -> AdcStatus:
        r = self._command("STAT?")
        return self._status_from(r, streaming=r.fields.get("state") == "streaming")

    def _status_from(self, r: Reply, streaming: bool) -> AdcStatus:
        try:
            return AdcStatus(
                streaming,
                int(r.fields.get("samples", 0)),
                int(r.fields.get("frames", 0)),
                int(r.fields.get("overruns", 0)),
            )
        except ValueError:
            fault = ProtocolError(f"ADC on {self.port}: status reply {r.text!r} is malformed")
            self.faults.report(fault)
            raise fault from None

    # ------------------------------------------------------------------ data
    def _contiguous(self) -> tuple[int, bool]:
        """Sets available before the next gap (or the end), and whether a gap/error follows them."""
        n = 0
        for item in self._items:
            if not isinstance(item, tuple):
                return n, True
            n += len(item[1])
        return n, False

    def read(self, n: int, timeout_s: float | None = None) -> AdcBlock:
        if not (isinstance(n, (int, np.integer)) and n > 0):
            raise ValueError(f"read {n!r} sample sets: the count must be a positive integer")
        cfg = self._config
        if cfg is None:
            raise InterlockError("the ADC is not configured")
        # A lost frame is only noticed when the next one arrives, so ask a virtual clock for a
        # frame more than needed, and for more still while nothing comes.
        ahead = cfg.frame_sets
        demanded = self._t0 + (self._read_pos + n + ahead) / cfg.rate_hz
        self.clock.demand(demanded)
        t_start = self._mono()
        with self._cond:
            while True:
                self._raise_queued()
                avail, blocked = self._contiguous()
                if avail >= n or (avail and (blocked or not self._rx_streaming)):
                    return self._take(min(n, avail), cfg)
                if not self._rx_streaming:
                    raise InterlockError(
                        f"the ADC stream has ended at sample {self._read_pos}; start it again"
                    )
                now = self._mono()
                if timeout_s is not None and now - t_start > timeout_s:
                    raise DeviceTimeout(
                        f"ADC on {self.port}: {n} sample sets not received within {timeout_s:g} s"
                    )
                if now - max(self._last_rx, t_start) > self.stall_timeout_s:
                    fault = DeviceTimeout(
                        f"ADC on {self.port} stalled: no data for {self.stall_timeout_s:g} s while "
                        f"streaming at {cfg.rate_hz:g} Hz (last sample {self._read_pos}); "
                        f"check the device and the cable"
                    )
                    self._report_unlocked(fault, stream_lost=True)
                    raise fault
                # Ask a virtual clock for more only once the rig got as far as asked and the frames
                # were lost on the way: asking because the host merely waited (a busy machine, a
                # slow pty) would run the physics further ahead, and a set-point sent next would
                # land at a rig time that depends on the machine's load.
                if (
                    not self._cond.wait(0.05)
                    and self.clock.virtual
                    and self.clock.now() >= demanded - 0.5 / cfg.rate_hz
                    and self._lost_in_flight(n, t_start)
                ):
                    ahead = min(2 * ahead, int(10 * cfg.rate_hz) + cfg.frame_sets)
                    demanded = self._t0 + (self._read_pos + n + ahead) / cfg.rate_hz
                    self.clock.demand(demanded)

    def _lost_in_flight(self, n: int, t_start: float) -> bool:
        """Whether the ``n`` sets a read waits for were lost rather than slow (caller holds
        _cond). ``STAT?``'s reply leaves the device behind every frame it queued before (one
        FIFO, docs/protocol.md 1.6), and the reader hands frames over in the order they came:
        once the reply is here, whatever is still missing will not come without more rig time.
        It is an in-band marker, so the answer is the same however slow the host or the pty.
        No reply (a stalled or silent device) is not a loss: the read's own rules decide."""
        self._cond.release()  # the reader needs _cond to hand over the frames ahead of the reply
        try:
            answered = self._marker(t_start)
        finally:
            self._cond.acquire()
        avail, blocked = self._contiguous()
        return answered and avail < n and not blocked and self._rx_streaming

    def _marker(self, t_start: float) -> bool:
        """Send ``STAT?`` and wait for its reply: True once it is in; False when the device
        sends nothing for the stall timeout (counted as a read counts it) or gives no reply
        within ``reply_timeout_s``. Not ``_command``: a missing answer here is no fault of its
        own; the read that asked reports the stall, with the read's words."""
        with self._cmd_lock:
            self._drop_stale_replies()
            self._send(encode_command("STAT?"), "STAT?")
            deadline = self._mono() + self.reply_timeout_s
            while True:
                try:
                    item = self._replies.get(timeout=0.05)
                except queue.Empty:
                    now = self._mono()
                    if now > deadline or now - max(self._last_rx, t_start) > self.stall_timeout_s:
                        return False
                    continue
                return isinstance(item, Reply) and item.ok and item.verb == "STAT"

    def read_available(self) -> AdcBlock | None:
        with self._cond:
            self._raise_queued()
            avail, _ = self._contiguous()
            if not avail:
                return None
            cfg = self._config
            if cfg is None:  # samples of an earlier stream, held past a reconfiguration that failed
                raise InterlockError("the ADC is not configured")
            return self._take(avail, cfg)

    def _raise_queued(self) -> None:
        """Raise a latched fault, or the gap or error at the head of the queue (caller holds _cond)."""
        self.faults.check()
        if self._items and not isinstance(self._items[0], tuple):
            item = self._items.popleft()
            if isinstance(item, SampleGap):
                self._read_pos = item.stop
            raise item

    def _report_unlocked(self, fault: DriverError, *, stream_lost: bool) -> None:
        """Latch ``fault`` (and end the stream if ``stream_lost``) with _cond, which the caller
        holds, released: the latch's listeners must not wait on this driver's lock."""
        self._cond.release()
        try:
            if stream_lost:
                self._lost(fault)
            else:
                self.faults.report(fault)
        finally:
            self._cond.acquire()

    def _take(self, n: int, cfg: AdcConfig) -> AdcBlock:
        """Pop n sets (caller holds _cond and has checked they are contiguous); ``cfg``: the configuration."""
        parts, got = [], 0
        first = self._items[0][0]
        while got < n:
            start, codes = self._items[0]
            k = min(n - got, len(codes))
            parts.append(codes[:k])
            if k == len(codes):
                self._items.popleft()
            else:
                self._items[0] = (start + k, codes[k:])
            got += k
        self._buffered -= n
        self._read_pos = first + n
        self._cond.notify_all()
        codes = parts[0] if len(parts) == 1 else np.concatenate(parts)
        # channel-major, as the run file stores it: the recorder's copy into its writer is then
        # a plain copy instead of a transpose, and a channel's column is contiguous; converting
        # this way costs the same (35-40 ms per 256 MB of volts measured either way)
        volts = np.empty((len(cfg.channels), len(codes)))
        np.multiply(codes.T, self._scale[:, None], out=volts)
        volts = volts.T
        over = (codes == CODE_MIN) | (codes == CODE_MAX)
        return AdcBlock(first, cfg.rate_hz, self._t0, cfg.channels, volts, over)

    # ------------------------------------------------------------------ lifetime
    def close(self) -> None:
        if self._closed:
            return
        if self._rx_streaming and self.faults.fault is None:
            try:
                self.stop()
            except DriverError as exc:
                log.warning("ADC on %s: stop on close failed: %s", self.port, exc)
        self._closed = True
        with self._cond:
            self._cond.notify_all()
        try:
            self.ser.close()
        except Exception:  # closing a port that already went away
            pass
        if self._thread is not threading.current_thread():
            self._thread.join(timeout=2.0)
