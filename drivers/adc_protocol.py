"""The ADC's serial protocol: ASCII commands, ASCII replies and binary sample frames.

The full specification, for firmware authors, is ``docs/protocol.md`` section 1. In short:

* host -> device: one ASCII command per line, ``\\n``-terminated (``IDN?``, ``CONF RATE 1000``).
* device -> host: ASCII reply lines (``OK ...`` or ``ERR <code> <text>``) and binary sample
  frames, never interleaved inside a frame. A frame is::

      offset  size  field
      0       2     sync 0xA5 0x5A
      2       1     type, 0x01 = sample frame
      3       1     channel count c (1..32)
      4       2     sample sets n (1..4096), uint16 LE
      6       2     flags, uint16 LE (bit 0: the device's FIFO overflowed before this frame)
      8       4     sequence counter, uint32 LE, +1 per frame since START, wraps
      12      8     index of the frame's first sample set since START, uint64 LE
      20      2nc   ADC codes, int16 LE, set-major (set 0: ch 0..c-1, set 1: ...)
      20+2nc  4     CRC-32 (IEEE 802.3, as zlib.crc32) of bytes 2 .. 20+2nc-1

Nothing here does I/O: the same code encodes on the device side (``simhw``) and decodes on
the host side (``drivers.serial_adc``), and hypothesis fuzzes the decoders.
"""

from __future__ import annotations

import functools
import re
import struct
import zlib
from dataclasses import dataclass, field

import numpy as np

from drivers.errors import ProtocolError

SYNC = b"\xa5\x5a"
TYPE_SAMPLES = 0x01
HEADER = struct.Struct("<2sBBHHIQ")
HEADER_SIZE = HEADER.size  # 20
CRC_SIZE = 4
MAX_CHANNELS = 32
MAX_SETS = 4096
MAX_LINE = 256
FLAG_OVERRUN = 0x0001
#: ADC code range (16-bit two's complement); the end codes mean "at or beyond full scale".
CODE_MIN, CODE_MAX = -32768, 32767

#: Error codes of ``ERR`` replies (docs/protocol.md 1.3).
ERR_CODES = ("SYNTAX", "UNKNOWN", "RANGE", "BUSY", "STATE", "INTERNAL")


@dataclass(frozen=True)
class Frame:
    """One decoded sample frame."""

    seq: int
    first_sample: int
    flags: int
    codes: np.ndarray  # (n_sets, n_channels) int16
    #: wire frames this item stands for: more than one only from a decoder that merges runs
    #: (``StreamDecoder(merge_runs=True)``), numbered ``seq`` .. ``seq + frames - 1``
    frames: int = 1

    @property
    def n_sets(self) -> int:
        return self.codes.shape[0]

    @property
    def n_channels(self) -> int:
        return self.codes.shape[1]


@dataclass(frozen=True)
class Reply:
    """One ASCII reply line: ``OK <verb> <words...>`` or ``ERR <code> <text>``."""

    ok: bool
    verb: str  # OK: echoed command keyword; ERR: the error code
    words: tuple[str, ...] = ()  # OK: tokens that are not key=value
    fields: dict[str, str] = field(default_factory=dict)  # OK: key=value tokens
    text: str = ""  # the whole line after the keyword

    def field(self, key: str) -> str:
        try:
            return self.fields[key]
        except KeyError:
            raise ProtocolError(
                f"ADC reply 'OK {self.verb} {self.text}' lacks the field {key!r}"
            ) from None


# --------------------------------------------------------------------------- frames
def encode_frame(seq: int, first_sample: int, codes: np.ndarray, flags: int = 0) -> bytes:
    """The bytes of one sample frame (device side)."""
    codes = np.asarray(codes)
    n, c = codes.shape
    if not (1 <= c <= MAX_CHANNELS and 1 <= n <= MAX_SETS):
        raise ValueError(
            f"frame of {n} sets x {c} channels is outside 1..{MAX_SETS} x 1..{MAX_CHANNELS}"
        )
    body = (
        HEADER.pack(SYNC, TYPE_SAMPLES, c, n, flags & 0xFFFF, seq & 0xFFFFFFFF, first_sample)
        + codes.astype("<i2", copy=False).tobytes()
    )
    return body + struct.pack("<I", zlib.crc32(memoryview(body)[2:]))


def encode_frames(
    seq: int, first_sample: int, codes: np.ndarray, sets: int, flags: int = 0
) -> bytes:
    """The bytes of consecutive frames of ``sets`` sample sets each (the last one shorter when
    ``codes`` does not divide), numbered from ``seq`` and ``first_sample``: exactly what
    :func:`encode_frame` gives frame by frame, built as one array (the sim rig's device spent a
    fifth of its physics thread packing 10 ms frames one by one)."""
    codes = np.asarray(codes)
    n, c = codes.shape
    if not (1 <= c <= MAX_CHANNELS and 1 <= sets <= MAX_SETS):
        raise ValueError(
            f"frames of {sets} sets x {c} channels are outside 1..{MAX_SETS} x 1..{MAX_CHANNELS}"
        )
    full = n // sets
    out = b""
    if full:
        rec = _record(sets, c)
        a = np.empty(full, rec)
        a["sync"], a["type"], a["c"], a["n"] = SYNC, TYPE_SAMPLES, c, sets
        a["flags"] = flags & 0xFFFF
        k = np.arange(full, dtype=np.uint64)
        a["seq"] = (seq + k) & 0xFFFFFFFF
        a["first"] = first_sample + sets * k
        a["codes"] = codes[: full * sets].reshape(full, sets, c)
        raw = a.data.cast("B")
        size = rec.itemsize
        a["crc"] = [zlib.crc32(raw[i * size + 2 : (i + 1) * size - CRC_SIZE]) for i in range(full)]
        out = a.tobytes()
    if full * sets < n:
        out += encode_frame(seq + full, first_sample + full * sets, codes[full * sets :], flags)
    return out


@functools.lru_cache(maxsize=64)
def _record(sets: int, c: int) -> np.dtype:
    """A frame of ``sets`` x ``c`` as a numpy record (the layout in the module docstring)."""
    return np.dtype(
        [
            ("sync", "S2"),
            ("type", "u1"),
            ("c", "u1"),
            ("n", "<u2"),
            ("flags", "<u2"),
            ("seq", "<u4"),
            ("first", "<u8"),
            ("codes", "<i2", (sets, c)),
            ("crc", "<u4"),
        ]
    )


def frame_size(n_sets: int, n_channels: int) -> int:
    return HEADER_SIZE + 2 * n_sets * n_channels + CRC_SIZE


def _check_header(
    ftype: int, c: int, n: int, expect_channels: int | None, max_sets: int = MAX_SETS
) -> str | None:
    if ftype != TYPE_SAMPLES:
        return f"unknown frame type 0x{ftype:02x}"
    if not 1 <= c <= MAX_CHANNELS:
        return f"bad length: channel count {c} outside 1..{MAX_CHANNELS}"
    if expect_channels is not None and c != expect_channels:
        return f"bad length: frame carries {c} channels, {expect_channels} are configured"
    if not 1 <= n <= max_sets:
        return f"bad length: {n} sample sets outside 1..{max_sets}"
    return None


def decode_frame(data: bytes, expect_channels: int | None = None) -> Frame:
    """Decode exactly one frame; any other byte string raises ProtocolError."""
    data = bytes(data)
    if len(data) < HEADER_SIZE + CRC_SIZE:
        raise ProtocolError(f"bad length: {len(data)} bytes is shorter than a frame header and CRC")
    sync, ftype, c, n, flags, seq, first = HEADER.unpack_from(data)
    if sync != SYNC:
        raise ProtocolError(f"bad sync bytes {sync.hex()} (expected a55a)")
    problem = _check_header(ftype, c, n, expect_channels)
    if problem:
        raise ProtocolError(problem)
    size = frame_size(n, c)
    if len(data) != size:
        raise ProtocolError(
            f"bad length: {len(data)} bytes for a frame of {n} sets x {c} channels ({size} bytes)"
        )
    return _finish_frame(data, 0, c, n, flags, seq, first)


def _finish_frame(
    buf: bytes | bytearray, pos: int, c: int, n: int, flags: int, seq: int, first: int
) -> Frame:
    end = pos + HEADER_SIZE + 2 * n * c
    (crc,) = struct.unpack_from("<I", buf, end)
    got = zlib.crc32(memoryview(buf)[pos + 2 : end])
    if got != crc:
        raise ProtocolError(
            f"bad CRC in frame seq {seq}: computed 0x{got:08x}, frame says 0x{crc:08x}"
        )
    codes = (
        np.frombuffer(buf, dtype="<i2", count=n * c, offset=pos + HEADER_SIZE).reshape(n, c).copy()
    )
    return Frame(seq, first, flags, codes)


# --------------------------------------------------------------------------- replies
_PRINTABLE = re.compile(rb"[\x20-\x7e]*\Z")  # \Z, not $: "$" also matches before a final "\n"


def decode_reply(line: bytes) -> Reply:
    """Decode one reply line (with or without its ``\\r\\n``); anything else raises ProtocolError."""
    raw = bytes(line)
    if raw.endswith(b"\n"):
        raw = raw[:-1]
    if raw.endswith(b"\r"):
        raw = raw[:-1]
    if len(raw) > MAX_LINE:
        raise ProtocolError(f"reply line of {len(raw)} bytes is longer than {MAX_LINE}")
    if not _PRINTABLE.match(raw):
        raise ProtocolError(f"reply {raw[:40]!r} holds non-printable bytes")
    text = raw.decode("ascii")
    head, _, rest = text.partition(" ")
    if head == "OK":
        verb, _, tail = rest.partition(" ")
        if not verb:
            raise ProtocolError(f"unknown reply {text!r}: 'OK' without the command keyword")
        words, fields = [], {}
        for tok in tail.split():
            k, eq, v = tok.partition("=")
            if eq and k:
                fields[k] = v
            else:
                words.append(tok)
        return Reply(True, verb, tuple(words), fields, tail)
    if head == "ERR":
        code, _, msg = rest.partition(" ")
        if code not in ERR_CODES:
            raise ProtocolError(
                f"unknown reply {text!r}: error code {code!r} is not one of {', '.join(ERR_CODES)}"
            )
        return Reply(False, code, text=msg)
    raise ProtocolError(f"unknown reply {text[:60]!r} (expected 'OK ...' or 'ERR ...')")


# --------------------------------------------------------------------------- the byte stream
_RESYNC = re.compile(rb"\xa5\x5a|OK[ \r\n]|ERR ")


class StreamDecoder:
    """Incremental decoder of the device -> host byte stream.

    ``feed(bytes)`` adds data; ``items()`` yields every complete unit as a ``Frame``, a
    ``Reply`` or a ``ProtocolError`` (returned, not raised, so one bad frame does not end the
    stream). After an error the decoder resynchronizes at the next sync pair or reply keyword;
    a run of garbage gives one error, not one per byte.

    With ``merge_runs`` a run of whole frames that continue one another (same shape, the next
    sequence number and first sample, no flags after the first, good CRCs) comes out as one
    ``Frame`` of all their sets (``frames`` counts them), checked as one array: the same
    samples, errors and replies as frame by frame. The host's 10 ms frames carry two sample
    sets at 200 Hz, and the sim rig's reader spent ~10 us on each frame, an eighth of a
    stopwatch's run.
    """

    def __init__(
        self,
        expect_channels: int | None = None,
        max_sets: int = MAX_SETS,
        *,
        merge_runs: bool = False,
    ) -> None:
        # What the host configured: a header claiming more is rejected at once, so a false
        # sync pair cannot make the decoder wait for a huge bogus frame.
        self.expect_channels = expect_channels
        self.max_sets = max_sets
        self.merge_runs = merge_runs
        self.buf = bytearray()
        self.pos = 0
        self.offset = 0  # stream offset of buf[0]
        self._bad = False  # inside a run of bytes already reported
        self._quiet_error: ProtocolError | None = None

    def feed(self, data: bytes) -> None:
        if self.pos > 1 << 16:
            del self.buf[: self.pos]
            self.offset += self.pos
            self.pos = 0
        self.buf += data

    def pending(self) -> int:
        """Bytes held that do not yet make a whole unit."""
        return len(self.buf) - self.pos

    def quiet(self) -> None:
        """The line went quiet with bytes held: a frame still waiting for its body will not be
        completed (its length field was corrupted), so report it and decode what follows."""
        if self.pending() and self.buf[self.pos] == 0xA5:
            err = self._error(
                f"bad length: frame header at stream offset {self.offset + self.pos} claims more "
                f"bytes than arrived before the line went quiet"
            )
            if err is not None:
                self._quiet_error = err

    def items(self):
        err, self._quiet_error = self._quiet_error, None
        if err is not None:
            yield err
        while True:
            item = self._next()
            if item is None:
                return
            yield item

    def _error(self, msg: str) -> ProtocolError | None:
        # Resume one byte on: a false keyword inside binary data must not swallow a good frame.
        at = self.offset + self.pos
        self._resync(self.pos + 1)
        if self._bad:
            return None
        self._bad = True
        return ProtocolError(f"{msg} (stream offset {at})", kind=msg.split(":")[0])

    def _resync(self, start: int) -> None:
        m = _RESYNC.search(self.buf, start)
        # Keep a possible partial keyword at the end for the next feed.
        self.pos = m.start() if m else max(start, len(self.buf) - 3)

    def _next(self) -> Frame | Reply | ProtocolError | None:
        while True:
            buf, pos = self.buf, self.pos
            avail = len(buf) - pos
            if avail <= 0:
                return None
            b0 = buf[pos]
            if b0 == 0xA5:
                if avail < 2:
                    return None
                if buf[pos + 1] != 0x5A:
                    err = self._error(
                        f"garbage: byte 0x{b0:02x} where a frame or reply should start"
                    )
                    if err:
                        return err
                    continue
                if avail < HEADER_SIZE:
                    return None
                _, ftype, c, n, flags, seq, first = HEADER.unpack_from(buf, pos)
                problem = _check_header(ftype, c, n, self.expect_channels, self.max_sets)
                if problem:
                    err = self._error(problem)
                    if err:
                        return err
                    continue
                size = frame_size(n, c)
                if avail < size:
                    return None
                try:
                    frame = _finish_frame(buf, pos, c, n, flags, seq, first)
                except ProtocolError as exc:
                    err = self._error(str(exc))
                    if err:
                        return err
                    continue
                self.pos = pos + size
                self._bad = False
                if self.merge_runs and len(buf) - self.pos >= size:
                    frame = self._merge_run(frame, size)
                return frame
            if b0 in (0x4F, 0x45):  # 'O', 'E'
                end = buf.find(b"\n", pos, pos + MAX_LINE + 2)
                if end < 0:
                    if avail <= MAX_LINE + 1:
                        return None
                    err = self._error("unknown reply: line longer than 256 bytes")
                    if err:
                        return err
                    continue
                line = bytes(buf[pos : end + 1])
                try:
                    reply = decode_reply(line)
                except ProtocolError as exc:
                    err = self._error(str(exc))
                    if err:
                        return err
                    continue
                self.pos = end + 1
                self._bad = False
                return reply
            err = self._error(f"garbage: byte 0x{b0:02x} where a frame or reply should start")
            if err:
                return err

    def _merge_run(self, frame: Frame, size: int) -> Frame:
        """``frame`` (just decoded, ``size`` bytes) with the whole frames after it that continue
        it, consumed: what frame-by-frame decoding gives, in one item. A frame that does not
        continue the run (another shape, a gap, a flag, a bad CRC) is left for ``_next``."""
        n, c = frame.codes.shape
        # whole frames held, no more than the u64 sample index can count on from this one (a
        # device whose index wraps is refused frame by frame, as it must be)
        k = min((len(self.buf) - self.pos) // size, (2**64 - 1 - frame.first_sample) // n)
        if k <= 0:
            return frame
        # a copy, not a view: a view would pin the bytearray, which ``feed`` resizes
        chunk = self.buf[self.pos : self.pos + k * size]
        a = np.frombuffer(chunk, dtype=_record(n, c), count=k)
        step = np.arange(1, k + 1, dtype=np.uint64)
        ok = (
            (a["sync"] == SYNC)
            & (a["type"] == TYPE_SAMPLES)
            & (a["c"] == c)
            & (a["n"] == n)
            & (a["flags"] == 0)
            & (a["seq"] == (frame.seq + step) % (1 << 32))
            & (a["first"] == frame.first_sample + n * step)
        )
        m = k if ok.all() else int(np.argmin(ok))
        raw, body = memoryview(chunk), size - 2 - CRC_SIZE
        got = [zlib.crc32(raw[at : at + body]) for at in range(2, m * size, size)]
        want = a["crc"][:m].tolist()
        if got != want:
            m = next(i for i, (g, w) in enumerate(zip(got, want)) if g != w)
        if m == 0:
            return frame
        self.pos += m * size
        codes = np.concatenate([frame.codes, a["codes"][:m].reshape(m * n, c)])
        return Frame(frame.seq, frame.first_sample, frame.flags, codes, frames=1 + m)


# --------------------------------------------------------------------------- commands
COMMANDS = ("IDN?", "CHAN?", "STAT?", "CONF", "START", "STOP")


@dataclass(frozen=True)
class Command:
    verb: str  # IDN?, CHAN?, STAT?, CONF, START, STOP
    args: tuple[str, ...]


def encode_command(verb: str, *args: object) -> bytes:
    if verb not in COMMANDS:
        raise ValueError(f"unknown ADC command {verb!r}")
    text = " ".join([verb, *(str(a) for a in args)])
    if len(text) > MAX_LINE or "\n" in text:
        raise ValueError(f"ADC command {text[:40]!r} is too long or holds a newline")
    return text.encode("ascii") + b"\n"


def encode_resync() -> bytes:
    """What the host sends first on every connection (docs/protocol.md 1.8): an empty line, which
    ends any partial command an earlier host left in the device's line buffer (the device answers
    it ``ERR SYNTAX``), then ``STOP``, whose ``OK STOP`` reply marks the end of whatever the device
    still had to send (frames of a stream nobody stopped, replies nobody read)."""
    return b"\n" + encode_command("STOP")


def decode_command(line: bytes) -> Command:
    """Device side: one command line -> Command, or ProtocolError (answered ``ERR SYNTAX``)."""
    raw = bytes(line).rstrip(b"\r\n")
    if len(raw) > MAX_LINE or not _PRINTABLE.match(raw):
        raise ProtocolError(f"command {raw[:40]!r} is too long or not printable ASCII")
    parts = raw.decode("ascii").split()
    if not parts:
        raise ProtocolError("empty command line")
    verb = parts[0].upper()
    if verb not in COMMANDS:
        raise ProtocolError(f"unknown command {parts[0]!r}")
    return Command(verb, tuple(parts[1:]))
