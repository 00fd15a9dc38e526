"""Connecting to an ADC that an earlier host left streaming (issue 19 point 11; docs/protocol.md 1.8).

A host process that dies (SIGKILL, a crash) sends no ``STOP``: the ADC streams on into a port
nobody reads, and its output waits wherever it was cut, mid-frame, with the replies to the
commands that were in flight queued behind the frames. The next host must still connect:
everything before its own ``OK STOP`` is discarded, then ``IDN?``, configure, ``START`` and a
stream that is continuous from its own ``START``.

Everything here runs over a real pseudo-terminal: the simulated ADC (``simhw.adc_device``) or,
for the devices that cannot be resynchronised, a bare pty written by the test. The device's
``hold`` stops its output as a USB device's stops when the host holding the port has died, so
the cut lands where the test wants it, and the rest reaches the next host only once it talks.
"""

from __future__ import annotations

import logging
import os
import re
import select
import signal
import subprocess
import sys
import threading
import tty
from pathlib import Path

import numpy as np
import pytest

from drivers.adc_protocol import encode_frame, frame_size
from drivers.errors import DeviceTimeout, ProtocolError
from drivers.serial_adc import SerialAdc
from simhw.rig_server import SimRigServer

pytestmark = pytest.mark.slow

RATE = 1000.0
FRAME = 10
FIRST = ["gyro_x", "torq_x", "ac_x_ctl"]  # the abandoned host's stream
SECOND = ["ac_y_ctl", "gyro_y", "torq_y", "pa_y"]  # the next host's: another frame width
REPO = Path(__file__).resolve().parents[2]


@pytest.fixture
def server():
    s = SimRigServer(rate_hz=RATE)
    yield s
    s.stop()


def abandon(adc: SerialAdc) -> None:
    """What the OS does to the port of a host process that died: closed, no STOP sent. The
    reader thread is told first, so it ends quietly instead of reporting a lost device."""
    adc._closed = True
    adc.ser.close()
    adc._thread.join(timeout=2.0)


def first_host(server: SimRigServer) -> SerialAdc:
    """A host that connects, configures, starts and reads, and whose last frame is through."""
    adc = SerialAdc(server.adc_port, clock=server.clock)
    adc.configure(FIRST, RATE, frame_sets=FRAME)
    t0 = adc.start()
    b = adc.read(200)
    assert b.first_sample == 0 and len(b) == 200
    server.wait_time(t0 + (200 + FRAME) / RATE)  # the frame read asks for ahead is made too
    return adc


def stream_on(server: SimRigServer, seconds: float) -> None:
    """The ADC keeps streaming, into a port nobody reads (its output holds)."""
    target = server.time_s + seconds
    server.demand(target)
    server.wait_time(target)


def second_host_streams(server: SimRigServer, n_reads: int = 3) -> None:
    """The next host: identity, configuration, START, and frames continuous from its START."""
    adc = SerialAdc(server.adc_port, clock=server.clock)
    try:
        assert adc.identity.model == "SIM-ADC16" and len(adc.identity.channels) == 19
        assert not adc.streaming
        assert adc.status().streaming is False
        cfg = adc.configure(SECOND, 2 * RATE, frame_sets=2 * FRAME)
        assert cfg.channels == tuple(SECOND)
        adc.start()
        pos = 0
        for _ in range(n_reads):
            b = adc.read(250)  # a SampleGap or an error here fails the test
            assert b.first_sample == pos and len(b) == 250 and b.channels == tuple(SECOND)
            assert np.all(np.isfinite(b.volts)) and np.abs(b.volts).max() <= 10.0
            pos = b.stop_sample
        status = adc.stop()
        while (b := adc.read_available()) is not None:
            assert b.first_sample == pos
            pos = b.stop_sample
        assert status.samples == pos and status.overruns == 0  # every set from its START, once
        assert adc.faults.fault is None
    finally:
        adc.close()
    assert server.adc.streaming is False


def test_a_fresh_adc_opens_quietly(server, caplog):
    """The resynchronisation at connect costs a clean device nothing: no warning, no stray reply."""
    with caplog.at_level(logging.WARNING, logger="drivers.serial_adc"):
        second_host_streams(server, n_reads=1)
    assert not [r for r in caplog.records if r.levelno >= logging.WARNING], caplog.text


CHILD = """
import sys
from drivers.serial_adc import SerialAdc
adc = SerialAdc(sys.argv[1])
adc.configure({chans!r}, {rate!r}, frame_sets={frame!r})
adc.start()
b = adc.read(200)
print("streaming", b.first_sample, len(b), flush=True)
sys.stdin.read()   # until killed
"""


def test_a_host_killed_mid_stream_leaves_an_adc_the_next_host_can_open():
    """The world's case: a host process streams from the ADC and is SIGKILLed. The device
    (paced, so it streams on by itself like hardware) goes on, its output cut mid-frame; the
    next host opens the same port and gets a correct IDN?, configuration and stream."""
    server = SimRigServer(rate_hz=RATE, realtime=True)
    child = None
    try:
        child = subprocess.Popen(
            [
                sys.executable,
                "-c",
                CHILD.format(chans=FIRST, rate=RATE, frame=FRAME),
                server.adc_port,
            ],
            cwd=REPO,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        assert child.stdout is not None and child.stderr is not None
        # a guard against a hung child, not a timing check: the child needs well under a second
        ready, _, _ = select.select([child.stdout], [], [], 60.0)
        line = child.stdout.readline() if ready else ""
        if line.split() != ["streaming", "0", "200"]:
            child.kill()
            pytest.fail(f"the first host did not stream: {line!r} {child.stderr.read()}")
        child.send_signal(signal.SIGKILL)
        child.wait()
        assert server.adc.streaming  # nobody said STOP
        # The port is closed now; what the device sends next stops half-way into a frame.
        server.adc.inject("hold", nbytes=frame_size(FRAME, len(FIRST)) // 2)
        server.wait_time(server.time_s + 0.3)  # 30 more frames wait in the device
        assert server.adc.streaming
        second_host_streams(server)
    finally:
        if child is not None:
            with child:  # its pipes closed and the process reaped, however the test ended
                if child.poll() is None:
                    child.kill()
        server.stop()


@pytest.mark.parametrize("cut", [1, 2, 19, 20, 50])
def test_next_host_opens_an_adc_left_mid_frame(server, cut):
    """The line starts with the tail of a frame (cut in the sync word, the header, the codes),
    then the frames the device made while nobody read."""
    host = first_host(server)
    server.adc.inject(
        "hold", nbytes=cut
    )  # the device's output stops `cut` bytes into its next frame
    stream_on(server, 0.05)
    abandon(host)
    stream_on(server, 2.0)
    second_host_streams(server)


def test_next_host_opens_an_adc_with_a_stale_reply_pending(server):
    """The dead host's last command (STAT?) was answered after it died: its reply waits in the
    device, between frames, and must not be taken for the next host's IDN? reply."""
    host = first_host(server)
    # The output stops mid-frame; released by the line below and the next host's first line.
    server.adc.inject("hold", count=2, nbytes=30)
    stream_on(server, 0.2)
    host.ser.write(b"STAT?\n")  # sent; the host dies before the reply
    stream_on(server, 0.3)
    abandon(host)
    stream_on(server, 0.5)
    second_host_streams(server)


def test_next_host_opens_an_adc_whose_stop_reply_was_never_read(server):
    """The dead host was stopping the stream: its own ``OK STOP`` waits in the device, ahead of
    the reply to the next host's STOP. The next host must not stop looking at the stale one."""
    host = first_host(server)
    server.adc.inject("hold", count=2, nbytes=30)
    stream_on(server, 0.2)
    host.ser.write(b"STOP\n")  # the device flushes its frames, then OK STOP
    stream_on(server, 0.2)
    abandon(host)
    second_host_streams(server)


def test_next_host_ends_a_partial_command_the_dead_host_left(server):
    """A host killed in the middle of writing a command leaves half a line in the device; the
    next host's first line must not be glued to it."""
    host = first_host(server)
    host.ser.write(b"CONF RA")
    abandon(host)
    second_host_streams(server)


# --------------------------------------------------------------------------- devices that never resynchronise
class FakeDevice:
    """A bare pty whose device side writes ``chunk`` again and again, and never answers."""

    def __init__(self, chunk: bytes | None) -> None:
        self.master, slave = os.openpty()
        tty.setraw(slave)
        os.set_blocking(self.master, False)
        self.port = os.ttyname(slave)
        self._slave = slave
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, args=(chunk,), daemon=True)
        self._thread.start()

    def _run(self, chunk: bytes | None) -> None:
        while not self._stop.is_set():
            if chunk is None:
                self._stop.wait(0.05)
                continue
            try:
                os.write(self.master, chunk)
            except BlockingIOError:
                self._stop.wait(0.001)
            except OSError:
                return

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        os.close(self.master)
        os.close(self._slave)


class ScriptedDevice(FakeDevice):
    """A bare pty that answers each command line with a canned reply, the first one preceded by
    ``lead`` (bytes a device left on the line)."""

    REPLIES = {
        b"": b"ERR SYNTAX empty command line\r\n",
        b"STOP": b"OK STOP samples=0 frames=0 overruns=0\r\n",
        b"STAT?": b"OK STAT state=idle rate=1000 channels=3 samples=0 frames=0 overruns=0\r\n",
        b"IDN?": b"OK IDN vendor=x model=SCRIPTED serial=1 fw=1 bits=16 max_rate_hz=1e6 ranges=10,1\r\n",
        b"CHAN?": b"OK CHAN a,b,c\r\n",
    }

    def __init__(self, lead: bytes) -> None:
        self.lead = lead
        super().__init__(None)

    def _run(self, chunk: bytes | None) -> None:
        buf, out = b"", self.lead
        while not self._stop.is_set():
            try:
                buf += os.read(self.master, 4096)
            except BlockingIOError:
                self._stop.wait(0.005)
                continue
            except OSError:
                return
            while b"\n" in buf:
                line, buf = buf.split(b"\n", 1)
                out += self.REPLIES.get(line.strip(), b"ERR UNKNOWN\r\n")
            if out:
                os.write(self.master, out)
                out = b""


@pytest.mark.parametrize(
    "lead",
    [
        encode_frame(0, 0, np.zeros((10, 3), dtype="<i2"))[:30],  # replies follow within its length
        encode_frame(0, 0, np.zeros((4096, 32), dtype="<i2"))[
            :30
        ],  # claims 262 kB: given up when quiet
    ],
    ids=["short-length", "huge-length"],
)
def test_the_head_of_a_frame_cut_short_does_not_swallow_the_stop_reply(lead):
    """A device reset mid-frame leaves the head of a frame: its length field claims bytes that
    are really the replies; the host still finds OK STOP in them and opens."""
    dev = ScriptedDevice(lead)
    try:
        adc = SerialAdc(dev.port)
        assert adc.identity.model == "SCRIPTED" and adc.identity.channels == ("a", "b", "c")
        adc.close()
    finally:
        dev.close()


NMEA = b"$GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,*47\r\n"
FRAMES = b"".join(encode_frame(i, 10 * i, np.full((10, 3), i, dtype="<i2")) for i in range(50))


@pytest.mark.parametrize(
    "chunk, what",
    [
        (NMEA, r"\$GPGGA,123519"),  # another device on the port: named by what it sends
        (FRAMES, r"[0-9]+ frames"),  # an ADC that streams on and never answers STOP
    ],
    ids=["another-device", "streams-on"],
)
def test_a_device_that_never_answers_stop_is_refused_with_what_it_sent(chunk, what):
    dev = FakeDevice(chunk)
    try:
        with pytest.raises(ProtocolError, match=r"cannot resynchroni[sz]e") as err:
            SerialAdc(dev.port, resync_bytes=1 << 16)
        msg = str(err.value)
        assert dev.port in msg and re.search(what, msg), msg
        assert "OK STOP" in msg and "power" in msg  # what was missing, and what to do
    finally:
        dev.close()


def test_a_silent_device_is_a_timeout_that_says_so():
    dev = FakeDevice(None)
    try:
        with pytest.raises(DeviceTimeout, match=r"no reply to STOP .*nothing at all"):
            SerialAdc(dev.port, reply_timeout_s=0.3)
    finally:
        dev.close()
