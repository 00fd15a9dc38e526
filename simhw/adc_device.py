"""The simulated ADC, on a pseudo-terminal: the device side of docs/protocol.md section 1.

The host driver opens ``port`` (the pty's slave path) like any serial device. A command
thread answers ASCII commands; the rig server's physics thread hands over each simulated
block (``on_block``), which is cut into CRC'd frames and queued for a writer thread. The
queue is the device's FIFO: on a virtual clock a full FIFO holds the simulation back; on a
paced clock it overflows like hardware (frames dropped, sequence counter still counting).

``inject`` makes the device misbehave on request, for the tests of every fault path.
``hold`` is the one that is not a fault of the device: it stops the output as a USB device's
stops when its host no longer reads (the host process died without ``STOP``), so a test can
leave the line mid-frame, or with a reply pending, for the next host to connect to.
"""

from __future__ import annotations

import errno
import logging
import os
import queue
import select
import threading
import tty
from typing import TYPE_CHECKING

import numpy as np

from drivers.adc_protocol import (
    CODE_MAX,
    CODE_MIN,
    FLAG_OVERRUN,
    MAX_CHANNELS,
    MAX_SETS,
    Command,
    ProtocolError,
    decode_command,
    encode_frame,
    encode_frames,
)
from simhw.plant import CHANNELS
from simhw.sampling import ADC_RANGES_V

if TYPE_CHECKING:
    from simhw.rig_server import SimRigServer

log = logging.getLogger(__name__)

FIRMWARE = "1.0"
FAULTS = ("drop", "corrupt", "bad_length", "garbage", "bad_reply", "stall", "disconnect", "hold")


class AdcDevice:
    def __init__(
        self,
        server: SimRigServer,
        max_aggregate_rate_hz: float = 2_000_000.0,
        fifo_bytes: int = 1 << 20,
    ) -> None:
        self.server = server
        self.max_aggregate_rate_hz = max_aggregate_rate_hz
        self.master, self._slave = os.openpty()
        tty.setraw(self._slave)
        os.set_blocking(self.master, False)
        self.port = os.ttyname(self._slave)
        self.channels: tuple[str, ...] = CHANNELS
        self.rate_hz = server.sim.rate_hz
        self.ranges = {c: server.sim.chain.ranges[c] for c in CHANNELS}
        self.frame_sets = max(1, min(MAX_SETS, round(self.rate_hz * 0.01)))
        self.streaming = False
        self.seq = self.samples = self.frames = self.overruns = 0
        self._overrun_flag = False
        self._fifo: queue.Queue = queue.Queue()
        self._fifo_bytes = 0
        self._fifo_limit = fifo_bytes
        self._fifo_cond = threading.Condition()
        self._faults: dict[str, int] = {}
        self._stall_until: float | None = None
        self._hold_lock = threading.Lock()
        self._hold_bytes: int | None = None  # bytes still to send before the output holds
        self._hold_lines = 0  # command lines to receive before it goes on
        self._connected = True
        self._stop = threading.Event()
        # a byte here wakes the command loop's select at disconnect (its threads are joined
        # there: a poll period each was most of closing the rig)
        self._wake_r, self._wake_w = os.pipe()
        self._threads = [
            threading.Thread(target=self._command_loop, name="sim-adc-commands", daemon=True),
            threading.Thread(target=self._write_loop, name="sim-adc-writer", daemon=True),
        ]
        for t in self._threads:
            t.start()

    # ------------------------------------------------------------------ faults
    def inject(
        self, fault: str, count: int = 1, seconds: float | None = None, nbytes: int = 64
    ) -> None:
        """Misbehave on purpose: ``drop``/``corrupt``/``bad_length`` the next ``count`` frames,
        write ``garbage`` bytes, answer the next command with a ``bad_reply``, ``stall`` (stop
        sending and answering, for ``seconds`` or for good), or ``disconnect`` (close the port).

        ``hold``: send ``nbytes`` more bytes of output (frames and replies alike, so a frame may
        be cut anywhere), then send nothing until ``count`` more command lines have arrived. It
        is what a USB device does when the host process holding the port dies mid-stream: its
        output waits, cut wherever it was, and the next host to talk to it gets the rest of the
        frame first, then everything queued meanwhile (frames, and replies to the commands that
        were in flight). Commands are still answered (into the FIFO) while the output holds."""
        if fault not in FAULTS:
            raise ValueError(f"unknown ADC fault {fault!r} (one of {', '.join(FAULTS)})")
        if fault == "hold":
            if count < 1 or nbytes < 0:
                raise ValueError(
                    f"hold needs count >= 1 command lines and nbytes >= 0 (got {count}, {nbytes})"
                )
            with self._hold_lock:
                self._hold_bytes, self._hold_lines = nbytes, count
        elif fault == "disconnect":
            self.disconnect()
        elif fault == "stall":
            now = self.server.wall()
            self._stall_until = float("inf") if seconds is None else now + seconds
        elif fault == "garbage":
            rng = np.random.default_rng(nbytes)
            junk = bytes(
                b
                for b in rng.integers(0, 256, 4 * nbytes, dtype=np.uint8).tolist()
                if b not in (0xA5, ord("O"), ord("E"))
            )[:nbytes]
            self._put(junk, control=True)
        else:
            self._faults[fault] = self._faults.get(fault, 0) + count

    def _take_fault(self, fault: str) -> bool:
        if self._faults.get(fault, 0) > 0:
            self._faults[fault] -= 1
            return True
        return False

    def _stalled(self) -> bool:
        if self._stall_until is None:
            return False
        if self.server.wall() >= self._stall_until:
            self._stall_until = None
            return False
        return True

    def _writable(self, want: int) -> int:
        """How many of ``want`` bytes the writer may send now (0 while the output holds)."""
        with self._hold_lock:
            if self._hold_bytes is None:
                return want
            return min(want, self._hold_bytes)

    def _sent(self, n: int) -> None:
        with self._hold_lock:
            if self._hold_bytes is not None:
                self._hold_bytes = max(0, self._hold_bytes - n)

    def _line_received(self) -> None:
        with self._hold_lock:
            if self._hold_bytes is not None:
                self._hold_lines -= 1
                if self._hold_lines <= 0:
                    self._hold_bytes = None

    def disconnect(self) -> None:
        """The cable is pulled: the port goes away under the host."""
        if not self._connected:
            return
        self._connected = False
        self._stop.set()
        with self._fifo_cond:
            self._fifo_cond.notify_all()
        self._fifo.put(b"")  # wakes the writer
        os.write(self._wake_w, b"x")  # wakes the command loop
        # Stop our threads before the descriptors go, so none acts on a reused fd number.
        for t in self._threads:
            if t is not threading.current_thread():
                t.join(timeout=1.0)
        for fd in (self.master, self._slave, self._wake_r, self._wake_w):
            try:
                os.close(fd)
            except OSError:
                pass

    # ------------------------------------------------------------------ output
    def _put(self, data: bytes, control: bool = False) -> bool:
        """Queue bytes for the writer. Returns False if a data frame was dropped (FIFO full)."""
        with self._fifo_cond:
            # An empty FIFO always takes a frame, however large.
            while (
                self._fifo_bytes
                and self._fifo_bytes + len(data) > self._fifo_limit
                and not control
                and self._connected
            ):
                if self.server.paced:
                    return False
                self._fifo_cond.wait(0.05)
            self._fifo_bytes += len(data)
        self._fifo.put(data)
        return True

    def _reply(self, text: str) -> None:
        if self._take_fault("bad_reply"):
            text = "OK HELLO from a confused device"
        self._put(text.encode("ascii") + b"\r\n", control=True)

    def _write_loop(self) -> None:
        while not self._stop.is_set():
            try:
                data = self._fifo.get(timeout=0.05)
            except queue.Empty:
                continue
            view = memoryview(data)
            while view and not self._stop.is_set():
                if self._stalled():
                    self._stop.wait(0.01)
                    continue
                allowed = self._writable(len(view))
                if not allowed:
                    self._stop.wait(0.01)
                    continue
                try:
                    n = os.write(self.master, view[:allowed])
                    self._sent(n)
                    view = view[n:]
                except BlockingIOError:
                    try:
                        select.select([], [self.master], [], 0.05)
                    except (OSError, ValueError):
                        return
                except OSError as exc:
                    if exc.errno in (errno.EIO, errno.EBADF):
                        return
                    raise
            with self._fifo_cond:
                self._fifo_bytes -= len(data)
                self._fifo_cond.notify_all()

    # ------------------------------------------------------------------ streaming (physics thread)
    def begin(self) -> None:
        self.streaming = True
        self.seq = self.samples = self.frames = self.overruns = 0
        self._overrun_flag = False
        self._reply(f"OK START samples=0 rate={self.rate_hz:.9g}")

    def end(self) -> None:
        self.streaming = False
        self._reply(f"OK STOP samples={self.samples} frames={self.frames} overruns={self.overruns}")

    def on_block(self, block) -> None:
        if not self.streaming or not self._connected:
            return
        cols = [block.channels.index(c) for c in self.channels]
        scale = np.array([32768.0 / self.ranges[c] for c in self.channels])
        codes = np.clip(np.rint(block.volts[:, cols] * scale), CODE_MIN, CODE_MAX).astype("<i2")
        codes[block.overrange[:, cols] & (block.volts[:, cols] > 0)] = CODE_MAX
        codes[block.overrange[:, cols] & (block.volts[:, cols] <= 0)] = CODE_MIN
        if self._plain():
            # the block's frames in one write: the same bytes as frame by frame
            nframes = -(-len(codes) // self.frame_sets)
            self._put(encode_frames(self.seq, self.samples, codes, self.frame_sets))
            self.seq = (self.seq + nframes) & 0xFFFFFFFF
            self.samples += len(codes)
            self.frames += nframes
            return
        for i in range(0, len(codes), self.frame_sets):
            chunk = codes[i : i + self.frame_sets]
            self._emit(chunk)

    def _plain(self) -> bool:
        """Frames go out as they are made: in virtual time (a full FIFO waits for the writer, it
        drops nothing), no frame fault armed, no stall, no overrun to flag."""
        return not (
            self.server.paced
            or self._overrun_flag
            or self._stall_until is not None
            or any(self._faults.get(f, 0) > 0 for f in ("drop", "bad_length", "corrupt"))
        )

    def _emit(self, chunk: np.ndarray) -> None:
        seq, first = self.seq, self.samples
        self.seq = (self.seq + 1) & 0xFFFFFFFF
        self.samples += len(chunk)
        if self._stalled() or self._take_fault("drop"):
            return  # lost on the way (or never sent): the counters still advanced
        flags = FLAG_OVERRUN if self._overrun_flag else 0
        if self._take_fault("bad_length"):
            data = encode_frame(seq, first, np.concatenate([chunk, chunk[:, :1]], axis=1), flags)
        else:
            data = encode_frame(seq, first, chunk, flags)
        if self._take_fault("corrupt"):
            b = bytearray(data)
            b[len(b) // 2] ^= 0x10
            data = bytes(b)
        if self._put(data):
            self.frames += 1
            self._overrun_flag = False
        else:
            self.overruns += 1
            self._overrun_flag = True

    # ------------------------------------------------------------------ commands
    def _command_loop(self) -> None:
        buf = bytearray()
        while not self._stop.is_set():
            try:
                r, _, _ = select.select([self.master, self._wake_r], [], [], 0.05)
                if self.master not in r:
                    continue
                data = os.read(self.master, 4096)
            except (OSError, ValueError):
                return
            if not data:
                continue
            buf += data
            while b"\n" in buf:
                line, _, rest = bytes(buf).partition(b"\n")
                buf = bytearray(rest)
                self._line_received()
                while self._stalled() and not self._stop.is_set():
                    self._stop.wait(0.01)
                if self._stop.is_set():
                    return  # stopped while stalled for good: the wait above would spin for ever
                try:
                    self._handle(decode_command(line))
                except ProtocolError as exc:
                    code = "UNKNOWN" if str(exc).startswith("unknown command") else "SYNTAX"
                    self._reply(f"ERR {code} {exc}"[:250])
                except Exception as exc:  # a device answers, it does not die
                    log.exception("simulated ADC: command %r failed", line)
                    self._reply(f"ERR INTERNAL {type(exc).__name__}")
            if len(buf) > 1024:
                buf.clear()
                self._reply("ERR SYNTAX line too long")

    def _handle(self, cmd: Command) -> None:
        a = cmd.args
        if cmd.verb == "IDN?":
            self._reply(
                f"OK IDN vendor=fbs-hil model=SIM-ADC16 serial=SIM-{self.server.seed:04d} fw={FIRMWARE} "
                f"bits=16 max_rate_hz={self.max_aggregate_rate_hz:.9g} "
                f"ranges={','.join(f'{r:g}' for r in ADC_RANGES_V)}"
            )
        elif cmd.verb == "CHAN?":
            self._reply("OK CHAN " + ",".join(CHANNELS))
        elif cmd.verb == "STAT?":
            self._reply(
                f"OK STAT state={'streaming' if self.streaming else 'idle'} rate={self.rate_hz:.9g} "
                f"channels={len(self.channels)} samples={self.samples} frames={self.frames} "
                f"overruns={self.overruns}"
            )
        elif cmd.verb == "START":
            if self.streaming:
                self._reply("ERR STATE already streaming")
            elif self.rate_hz * len(self.channels) > self.max_aggregate_rate_hz:
                self._reply(
                    f"ERR RANGE {len(self.channels)} channels at {self.rate_hz:g} Hz exceed "
                    f"{self.max_aggregate_rate_hz:g} samples/s"
                )
            else:
                self.server.submit(lambda sim: self.begin())
        elif cmd.verb == "STOP":
            if not self.streaming:
                self._reply(
                    f"OK STOP samples={self.samples} frames={self.frames} overruns={self.overruns}"
                )
            else:
                self.server.submit(lambda sim: self.end())
        elif cmd.verb == "CONF":
            self._configure(a)

    def _configure(self, a: tuple[str, ...]) -> None:
        if self.streaming:
            self._reply("ERR BUSY stop the stream before reconfiguring")
            return
        what = a[0].upper() if a else ""
        if what == "CHAN" and len(a) == 2:
            chans = tuple(a[1].split(","))
            bad = [c for c in chans if c not in CHANNELS]
            # The channels x rate limit is checked at START, so CONF order does not matter.
            if bad or not chans or len(set(chans)) != len(chans) or len(chans) > MAX_CHANNELS:
                self._reply(f"ERR RANGE channel list {a[1][:80]} (unknown: {','.join(bad)[:80]})")
            else:
                self.channels = chans
                self._reply(f"OK CONF CHAN {','.join(chans)}")
        elif what == "RATE" and len(a) == 2:
            try:
                rate = float(a[1])
            except ValueError:
                rate = float("nan")
            if not (0 < rate <= self.max_aggregate_rate_hz):
                self._reply(
                    f"ERR RANGE rate {a[1]} Hz (0 < rate <= {self.max_aggregate_rate_hz:g})"
                )
            else:
                self.rate_hz = rate
                self.server.submit(lambda sim: sim.set_rate(rate))
                self._reply(f"OK CONF RATE {rate:.9g}")
        elif what == "RANGE" and len(a) == 3:
            try:
                r = float(a[2])
            except ValueError:
                r = float("nan")
            if a[1] not in CHANNELS or r not in ADC_RANGES_V:
                self._reply(f"ERR RANGE range {a[2]} V for {a[1]}")
            else:
                self.ranges[a[1]] = r
                ch = a[1]
                self.server.submit(lambda sim: sim.set_range(ch, r))
                self._reply(f"OK CONF RANGE {ch} {r:g}")
        elif what == "FRAME" and len(a) == 2:
            try:
                n = int(a[1])
            except ValueError:
                n = 0
            if not 1 <= n <= MAX_SETS:
                self._reply(f"ERR RANGE frame length {a[1]} (1..{MAX_SETS})")
            else:
                self.frame_sets = n
                self._reply(f"OK CONF FRAME {n}")
        else:
            self._reply(f"ERR SYNTAX CONF {' '.join(a)[:80]}")

    def close(self) -> None:
        self.disconnect()
