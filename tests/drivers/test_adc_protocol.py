"""The ADC's serial protocol: frame, reply and command parsers, and the incremental stream decoder.

Acceptance point: hypothesis fuzzes the frame and reply parsers, and any byte string gives
either a valid frame (or reply) or a :class:`ProtocolError`, never another exception and never
a hang. Inputs are bounded and every fuzz test runs under a hypothesis deadline, so a parser
that is slow fails the test instead of passing slowly; the stream decoder, the one parser with
a loop, also runs under ``_ProgressGuard``, which turns a loop that stops consuming input into
an AssertionError instead of a hung test run. Every "valid" result is checked against the bytes
it came from (a decoded frame re-encodes to exactly its input), so a parser that accepted junk
would fail too.
"""

from __future__ import annotations

import itertools
import re
import struct
import sys
import zlib

import numpy as np
import pytest
from hypothesis import assume, example, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from drivers import adc_protocol
from drivers.adc_protocol import (
    CODE_MAX,
    CODE_MIN,
    COMMANDS,
    CRC_SIZE,
    ERR_CODES,
    FLAG_OVERRUN,
    HEADER_SIZE,
    MAX_CHANNELS,
    MAX_LINE,
    MAX_SETS,
    SYNC,
    Command,
    Frame,
    Reply,
    StreamDecoder,
    decode_command,
    decode_frame,
    decode_reply,
    encode_command,
    encode_frame,
    encode_frames,
    frame_size,
)
from drivers.errors import ProtocolError

#: Fuzz settings: bounded inputs, and a generous deadline so a parser that spins fails.
FUZZ = settings(max_examples=300, deadline=500)
FAST = settings(max_examples=100, deadline=500)
SLOW = settings(max_examples=40, deadline=1000)

PRINTABLE = re.compile(r"[\x20-\x7e]*\Z")


# --------------------------------------------------------------------------- helpers
def _outcome(fn, *args):
    """The parser's result, or the ProtocolError it raised. Any other exception escapes (and fails)."""
    try:
        return fn(*args)
    except ProtocolError as exc:
        return exc


def _frame_tuple(f: Frame):
    return (f.seq, f.first_sample, f.flags, f.codes.dtype.str, f.codes.shape, f.codes.tobytes())


def _expected_tuple(seq, first, flags, codes):
    codes = np.asarray(codes, dtype="<i2")
    return (seq, first, flags, "<i2", codes.shape, codes.tobytes())


def _item_key(item):
    """A comparable form of a StreamDecoder item."""
    if isinstance(item, Frame):
        return ("frame", _frame_tuple(item))
    if isinstance(item, Reply):
        return (
            "reply",
            item.ok,
            item.verb,
            item.words,
            tuple(sorted(item.fields.items())),
            item.text,
        )
    assert isinstance(item, ProtocolError), f"StreamDecoder yielded {type(item).__name__}: {item!r}"
    return ("error", str(item))


def _run_stream(chunks, expect_channels=None, max_sets=MAX_SETS):
    """Feed chunks one by one and collect every item, checking the decoder's invariants.

    * items() always ends (it is a finite generator; ``islice`` turns an endless one into a
      failure here instead of a hang), and never yields more items than bytes were fed;
    * the stream position (``offset + pos``) only moves forward and never passes the bytes fed;
    * the decoder never runs long without consuming input (``_ProgressGuard``).
    """
    d = StreamDecoder(expect_channels, max_sets)
    fed = 0
    last = 0
    out = []
    with _ProgressGuard(d):
        for chunk in chunks:
            d.feed(chunk)
            fed += len(chunk)
            assert d.offset + d.pos == last, "feed() moved the stream position"
            batch = list(itertools.islice(d.items(), fed + 1))
            assert len(out) + len(batch) <= fed, (
                "more items than bytes: the decoder is not consuming input"
            )
            for item in batch:
                assert isinstance(item, (Frame, Reply, ProtocolError)), type(item)
            out.extend(batch)
            here = d.offset + d.pos
            assert last <= here <= fed
            assert d.offset + len(d.buf) == fed
            last = here
    return d, out


class _ProgressGuard:
    """Fail, instead of hanging, if the decoder runs many lines without consuming input.

    A deterministic "never a hang" check (no wall clock): while active, every line run inside
    adc_protocol.py is counted, and the count starts again whenever the decoder's stream
    position (``offset + pos``) passes its furthest point so far. Every pass of the decoding
    loop either consumes a byte or stops, so ``LIMIT`` lines without progress means a loop that
    no longer terminates; it raises AssertionError there.
    """

    # Lines, not statements: a statement wrapped over several lines counts each (the longest
    # honest stretch measured on this test is 2,011 lines); a hang counts without end.
    LIMIT = 10_000

    def __init__(self, decoder: StreamDecoder) -> None:
        self.d = decoder
        self.best = decoder.offset + decoder.pos
        self.lines = 0

    def _local(self, frame, event, arg):
        if event == "line":
            here = self.d.offset + self.d.pos
            if here > self.best:
                self.best, self.lines = here, 0
            else:
                self.lines += 1
                if self.lines > self.LIMIT:
                    raise AssertionError(
                        f"the decoder ran {self.LIMIT} lines without consuming a byte "
                        f"(stuck at stream offset {here}): it would never return"
                    )
        return self._local

    def _global(self, frame, event, arg):
        return self._local if frame.f_code.co_filename == adc_protocol.__file__ else None

    def __enter__(self):
        self._saved = sys.gettrace()
        sys.settrace(self._global)
        return self

    def __exit__(self, *exc):
        sys.settrace(self._saved)
        return False


def _cut(data: bytes, cuts) -> list[bytes]:
    points = sorted({c % (len(data) + 1) for c in cuts})
    bounds = [0, *points, len(data)]
    return [data[a:b] for a, b in itertools.pairwise(bounds)]


# --------------------------------------------------------------------------- strategies
seqs = st.integers(0, 2**32 - 1)
firsts = st.integers(0, 2**64 - 1)
flag_words = st.integers(0, 0xFFFF)
int16 = st.integers(CODE_MIN, CODE_MAX)


def code_arrays(max_sets=64, max_channels=MAX_CHANNELS):
    shapes = st.tuples(st.integers(1, max_sets), st.integers(1, max_channels))
    return hnp.arrays(np.int16, shapes, elements=int16)


@st.composite
def frame_args(draw, max_sets=64, max_channels=MAX_CHANNELS):
    return (draw(seqs), draw(firsts), draw(flag_words), draw(code_arrays(max_sets, max_channels)))


small_frames = frame_args(max_sets=6, max_channels=4)


@st.composite
def mutated_frames(draw):
    """A valid small frame with a few random edits (flip, overwrite, cut, grow, insert, delete)."""
    seq, first, flags, codes = draw(small_frames)
    b = bytearray(encode_frame(seq, first, codes, flags))
    for _ in range(draw(st.integers(1, 4))):
        op = draw(st.sampled_from(["flip", "set", "truncate", "extend", "insert", "delete"]))
        i = draw(st.integers(0, max(0, len(b) - 1)))
        if op == "flip" and b:
            b[i] ^= 1 << draw(st.integers(0, 7))
        elif op == "set" and b:
            b[i] = draw(st.integers(0, 255))
        elif op == "truncate":
            del b[i:]
        elif op == "extend":
            b += draw(st.binary(min_size=1, max_size=8))
        elif op == "insert":
            b[i:i] = draw(st.binary(min_size=1, max_size=4))
        elif op == "delete" and b:
            del b[i]
    return bytes(b)


@st.composite
def header_prefixed(draw):
    """Sync + a plausible header + random body of about the right length (with or without a good CRC)."""
    ftype = draw(st.sampled_from([1, 1, 1, 1, 0, 2, 0xFF]))
    c = draw(st.sampled_from([1, 1, 2, 3, 32, 0, 33, 255]))
    n = draw(st.sampled_from([1, 1, 2, 5, 0, 4096, 4097, 0xFFFF]))
    head = struct.pack("<2sBBHHIQ", SYNC, ftype, c, n, draw(flag_words), draw(seqs), draw(firsts))
    body_len = 2 * n * c if n * c <= 64 else draw(st.integers(0, 64))
    body_len = max(0, body_len + draw(st.sampled_from([0, 0, 0, -2, -1, 1, 2])))
    body = draw(st.binary(min_size=body_len, max_size=body_len))
    data = head + body
    if draw(st.booleans()):
        data += struct.pack("<I", zlib.crc32(data[2:]))
    else:
        data += draw(st.binary(max_size=6))
    return data


valid_frames = small_frames.map(lambda a: encode_frame(a[0], a[1], a[3], a[2]))
frame_fuzz = st.one_of(st.binary(max_size=400), mutated_frames(), header_prefixed(), valid_frames)

reply_alphabet = st.sampled_from(
    [
        b"OK",
        b"ERR",
        b" ",
        b"=",
        b"a",
        b"IDN",
        b"RANGE",
        b"x=1",
        b"\r",
        b"\n",
        b"\x00",
        b"\x7f",
        b"\xff",
        b"\t",
        b"~",
        *(c.encode() for c in ERR_CODES),
    ]
)
reply_like = st.lists(reply_alphabet, max_size=12).map(b"".join)
reply_fuzz = st.one_of(
    st.binary(max_size=300),
    reply_like,
    st.builds(
        lambda a, b: a + b,
        st.sampled_from([b"OK ", b"ERR ", b"OK", b"ERR"]),
        st.binary(max_size=40),
    ),
    st.integers(MAX_LINE - 3, MAX_LINE + 3).map(lambda k: b"OK X " + b"y" * (k - 5)),
)

token = st.text(st.characters(min_codepoint=0x21, max_codepoint=0x7E), min_size=1, max_size=12)
key = st.text(
    st.characters(min_codepoint=0x21, max_codepoint=0x7E, exclude_characters="="),
    min_size=1,
    max_size=6,
)
word = token.filter(lambda t: "=" not in t)
printable_text = st.text(st.characters(min_codepoint=0x20, max_codepoint=0x7E), max_size=60)


@st.composite
def reply_lines(draw):
    """A well-formed reply line and the Reply it must decode to."""
    ending = draw(st.sampled_from([b"\n", b"\r\n"]))
    if draw(st.booleans()):
        verb = draw(word)
        fields = draw(
            st.dictionaries(
                key,
                st.text(st.characters(min_codepoint=0x21, max_codepoint=0x7E), max_size=8),
                max_size=4,
            )
        )
        words = draw(st.lists(word, max_size=4))
        toks = [f"{k}={v}" for k, v in fields.items()] + words
        toks = draw(st.permutations(toks))
        tail = " ".join(toks)
        want_words = tuple(t for t in toks if "=" not in t)
        want = Reply(True, verb, want_words, dict(fields), tail)
        line = f"OK {verb} {tail}" if tail else f"OK {verb}"
    else:
        code = draw(st.sampled_from(ERR_CODES))
        text = draw(printable_text)
        want = Reply(False, code, text=text)
        line = f"ERR {code} {text}"
    assume(len(line) <= MAX_LINE)
    return line.encode("ascii") + ending, want


# =========================================================================== frames
@FAST
@given(frame_args())
@example((0, 0, 0, np.full((1, 1), CODE_MIN, np.int16)))
@example((2**32 - 1, 2**64 - 1, 0xFFFF, np.full((64, 32), CODE_MAX, np.int16)))
@example((7, 3, 1, np.array([[CODE_MIN, CODE_MAX, 0, -1]], np.int16)))
def test_encoded_frame_decodes_to_the_same_seq_first_sample_flags_and_codes(args):
    """encode_frame -> decode_frame is exact for 1..32 channels x 1..64 sets, full int16 range."""
    seq, first, flags, codes = args
    data = encode_frame(seq, first, codes, flags)
    assert len(data) == frame_size(*codes.shape) == HEADER_SIZE + 2 * codes.size + CRC_SIZE
    f = decode_frame(data)
    assert isinstance(f, Frame)
    assert (f.seq, f.first_sample, f.flags) == (seq, first, flags)
    assert f.codes.dtype == np.dtype("<i2")
    assert (f.n_sets, f.n_channels) == codes.shape
    np.testing.assert_array_equal(f.codes, codes)
    assert decode_frame(data, expect_channels=codes.shape[1]).seq == seq


@FAST
@given(
    st.integers(0, 2**32 - 1),
    st.integers(0, 2**63),
    st.integers(0, 0xFFFF),
    st.integers(1, 16),
    hnp.arrays(np.int16, st.tuples(st.integers(1, 80), st.integers(1, MAX_CHANNELS))),
)
@example(2**32 - 2, 0, 1, 2, np.zeros((7, 3), np.int16))  # the counter wraps inside the block
def test_a_block_of_frames_is_its_frames_one_by_one(seq, first, flags, sets, codes):
    """encode_frames (the device's block at once) gives the bytes encode_frame gives frame by
    frame, the last frame short when the block does not divide."""
    one_by_one = b"".join(
        encode_frame(seq + i, first + i * sets, codes[k : k + sets], flags)
        for i, k in enumerate(range(0, len(codes), sets))
    )
    assert encode_frames(seq, first, codes, sets, flags) == one_by_one


def test_frame_layout_matches_the_specification_byte_for_byte():
    """The documented wire layout: sync, type, c, n, flags, seq, first sample, set-major codes, CRC."""
    codes = np.array([[1, -2], [0x1234, CODE_MIN], [CODE_MAX, 0]], np.int16)  # 3 sets x 2 channels
    data = encode_frame(0x01020304, 0x1122334455667788, codes, flags=0x0001)
    assert data[:2] == b"\xa5\x5a"
    assert data[2] == 0x01 and data[3] == 2
    assert data[4:6] == b"\x03\x00" and data[6:8] == b"\x01\x00"
    assert data[8:12] == b"\x04\x03\x02\x01"
    assert data[12:20] == bytes.fromhex("8877665544332211")
    assert data[20:32] == bytes.fromhex("0100feff34120080ff7f0000")
    assert data[32:] == struct.pack("<I", zlib.crc32(data[2:32]))
    assert len(data) == 36


def test_largest_and_smallest_frames_round_trip():
    """The shape limits 1x1 and 4096 sets x 32 channels both decode."""
    for shape in [(1, 1), (MAX_SETS, MAX_CHANNELS)]:
        codes = (np.arange(np.prod(shape)) % 65536 - 32768).astype(np.int16).reshape(shape)
        f = decode_frame(encode_frame(5, 6, codes))
        np.testing.assert_array_equal(f.codes, codes)


@pytest.mark.parametrize("shape", [(0, 1), (1, 0), (MAX_SETS + 1, 1), (1, MAX_CHANNELS + 1)])
def test_encoder_refuses_shapes_outside_the_protocol(shape):
    """The device side cannot emit a frame the host would have to reject for its shape."""
    with pytest.raises(ValueError, match="outside"):
        encode_frame(0, 0, np.zeros(shape, np.int16))


@FUZZ
@given(frame_fuzz, st.none() | st.integers(1, MAX_CHANNELS))
@example(b"", None)
@example(b"\xa5\x5a" + b"\x00" * 22, None)
@example(encode_frame(1, 2, np.zeros((2, 3), np.int16))[:-1], None)
@example(encode_frame(1, 2, np.zeros((2, 3), np.int16)), 4)
def test_decode_frame_gives_a_valid_frame_or_a_protocol_error_for_any_bytes(data, expect):
    """Any byte string: a Frame that re-encodes to exactly those bytes, or ProtocolError; nothing else."""
    got = _outcome(decode_frame, data, expect)
    if isinstance(got, ProtocolError):
        assert str(got)
        return
    assert isinstance(got, Frame)
    assert encode_frame(got.seq, got.first_sample, got.codes, got.flags) == data
    assert 1 <= got.n_channels <= MAX_CHANNELS and 1 <= got.n_sets <= MAX_SETS
    if expect is not None:
        assert got.n_channels == expect


@FAST
@given(frame_args(max_sets=8, max_channels=6), st.data())
def test_any_single_bit_flip_makes_decode_frame_raise(args, data):
    """CRC-32 plus the header checks catch every single-bit error in a frame."""
    seq, first, flags, codes = args
    b = bytearray(encode_frame(seq, first, codes, flags))
    bit = data.draw(st.integers(0, 8 * len(b) - 1), label="bit")
    b[bit // 8] ^= 1 << (bit % 8)
    with pytest.raises(ProtocolError, match="bad (CRC|sync|length)|unknown frame type"):
        decode_frame(bytes(b))


def test_every_single_bit_flip_is_reported_with_the_right_reason():
    """Exhaustively, per field: sync -> bad sync, type -> frame type, c/n -> bad length, rest -> bad CRC."""
    good = encode_frame(0xDEADBEEF, 12345, np.array([[1, 2, 3], [-4, -5, -6]], np.int16), flags=1)
    reasons = {}
    for bit in range(8 * len(good)):
        b = bytearray(good)
        b[bit // 8] ^= 1 << (bit % 8)
        with pytest.raises(ProtocolError) as info:
            decode_frame(bytes(b))
        reasons.setdefault(bit // 8, set()).add(str(info.value).split(":")[0].split(" in ")[0])
    for i in (0, 1):
        assert all(r.startswith("bad sync bytes") for r in reasons[i]), reasons[i]
    assert all(r.startswith("unknown frame type") for r in reasons[2])
    for i in (3, 4, 5):
        assert reasons[i] == {"bad length"}, (i, reasons[i])
    for i in range(6, len(good)):
        assert reasons[i] == {"bad CRC"}, (i, reasons[i])


def test_decode_frame_messages_name_the_problem():
    """Short input, bad sync, bad type, channel count, set count, configured channels, size, CRC."""
    good = encode_frame(3, 0, np.zeros((2, 2), np.int16))
    cases = [
        (good[:23], "bad length: 23 bytes is shorter than a frame header and CRC"),
        (b"\x5a\xa5" + good[2:], "bad sync bytes 5aa5"),
        (good[:2] + b"\x02" + good[3:], "unknown frame type 0x02"),
        (good[:3] + b"\x00" + good[4:], "channel count 0 outside 1..32"),
        (good[:3] + b"\x21" + good[4:], "channel count 33 outside 1..32"),
        (good[:4] + b"\x00\x00" + good[6:], "0 sample sets outside 1..4096"),
        (good[:4] + b"\x01\x10" + good[6:], "4097 sample sets outside 1..4096"),
        (good + b"\x00", "bad length: 33 bytes for a frame of 2 sets x 2 channels (32 bytes)"),
        (good[:-1] + bytes([good[-1] ^ 0x80]), "bad CRC in frame seq 3"),
    ]
    for data, msg in cases:
        with pytest.raises(ProtocolError, match=re.escape(msg)):
            decode_frame(data)
    with pytest.raises(
        ProtocolError, match=re.escape("frame carries 2 channels, 3 are configured")
    ):
        decode_frame(good, expect_channels=3)


# =========================================================================== replies
def test_ok_reply_parses_verb_fields_and_words():
    """`OK IDN a=1 b=2 word`: verb IDN, fields a and b, the bare token as a word."""
    for line in (b"OK IDN a=1 b=2 word", b"OK IDN a=1 b=2 word\n", b"OK IDN a=1 b=2 word\r\n"):
        r = decode_reply(line)
        assert r.ok is True
        assert r.verb == "IDN"
        assert r.fields == {"a": "1", "b": "2"}
        assert r.words == ("word",)
        assert r.text == "a=1 b=2 word"
        assert r.field("b") == "2"
    with pytest.raises(ProtocolError, match="lacks the field 'c'"):
        r.field("c")


def test_reply_tokens_with_empty_key_or_value():
    """`=x` is a word (no key); `k=` is a field with an empty value; `a=b=c` keeps `b=c` as the value."""
    r = decode_reply(b"OK CONF =x k= a=b=c")
    assert r.words == ("=x",)
    assert r.fields == {"k": "", "a": "b=c"}


def test_err_reply_parses_code_and_text():
    """`ERR RANGE text`: not ok, the code as verb, the rest as text; every documented code parses."""
    r = decode_reply(b"ERR RANGE frame length 5000 (1..4096)\r\n")
    assert (r.ok, r.verb, r.text, r.words, r.fields) == (
        False,
        "RANGE",
        "frame length 5000 (1..4096)",
        (),
        {},
    )
    for code in ERR_CODES:
        assert decode_reply(f"ERR {code} text".encode()) == Reply(False, code, text="text")
    assert decode_reply(b"ERR BUSY") == Reply(False, "BUSY", text="")


@pytest.mark.parametrize(
    "line, problem",
    [
        (
            b"ERR NOPE something",
            "error code 'NOPE' is not one of SYNTAX, UNKNOWN, RANGE, BUSY, STATE, INTERNAL",
        ),
        (b"ERR range lower case", "error code 'range' is not one of"),
        (b"ERR", "error code '' is not one of"),
        (b"OK IDN \x00", "holds non-printable bytes"),
        (b"OK IDN caf\xc3\xa9", "holds non-printable bytes"),
        (b"OK IDN\ttab", "holds non-printable bytes"),
        (b"OK IDN\x7f", "holds non-printable bytes"),
        (b"OK IDN\n\n", "holds non-printable bytes"),
        (b"ERR RANGE x\n\n", "holds non-printable bytes"),
        (b"OK IDN\r\r\n", "holds non-printable bytes"),
        (b"OK X " + b"y" * (MAX_LINE - 4), "reply line of 257 bytes is longer than 256"),
        (b"OK X " + b"y" * 1000 + b"\r\n", "reply line of 1005 bytes is longer than 256"),
        (b"HELLO there", "unknown reply 'HELLO there' (expected 'OK ...' or 'ERR ...')"),
        (b"ok idn", "unknown reply 'ok idn'"),
        (b"OKAY", "unknown reply 'OKAY'"),
        (b" OK IDN", "unknown reply ' OK IDN'"),
        (b"", "unknown reply ''"),
        (b"\n", "unknown reply ''"),
        (b"OK", "'OK' without the command keyword"),
        (b"OK  IDN", "'OK' without the command keyword"),
    ],
)
def test_bad_replies_raise_a_protocol_error_that_names_the_problem(line, problem):
    """Unknown codes, non-printable bytes, over-long lines and foreign lines are each named."""
    with pytest.raises(ProtocolError, match=re.escape(problem)):
        decode_reply(line)


def test_reply_of_exactly_max_line_bytes_is_accepted():
    """256 printable bytes (plus CR LF) is the longest legal line."""
    line = b"OK X " + b"y" * (MAX_LINE - 5)
    assert len(line) == MAX_LINE
    assert decode_reply(line + b"\r\n").words == ("y" * (MAX_LINE - 5),)


@FAST
@given(reply_lines())
def test_well_formed_reply_lines_decode_to_their_parts(pair):
    """Generated OK/ERR lines (either line ending) decode to exactly the verb, words, fields and text."""
    line, want = pair
    assert decode_reply(line) == want


@FUZZ
@given(reply_fuzz)
@example(b"OK IDN\n\n")
@example(b"ERR STATE x\n\n")
@example(b"OK A=\n")
def test_decode_reply_gives_a_valid_reply_or_a_protocol_error_for_any_bytes(line):
    """Any byte string: a Reply made only of printable ASCII and consistent with the line, or ProtocolError."""
    got = _outcome(decode_reply, line)
    if isinstance(got, ProtocolError):
        assert str(got)
        return
    assert isinstance(got, Reply)
    body = line[:-1] if line.endswith(b"\n") else line
    body = body[:-1] if body.endswith(b"\r") else body
    assert len(body) <= MAX_LINE
    for s in (got.verb, got.text, *got.words, *got.fields, *got.fields.values()):
        assert PRINTABLE.match(s), f"decoded reply holds a non-printable character: {got!r}"
    assert got.verb and " " not in got.verb
    if got.ok:
        assert body.decode("ascii") == f"OK {got.verb} {got.text}" or (
            not got.text and body.decode("ascii") in (f"OK {got.verb}", f"OK {got.verb} ")
        )
        toks = got.text.split()
        assert len(got.words) + len(got.fields) <= len(toks)
        for w in got.words:
            assert w in toks
    else:
        assert got.verb in ERR_CODES
        assert body.decode("ascii") in (f"ERR {got.verb} {got.text}", f"ERR {got.verb}")
        assert got.words == () and got.fields == {}


# =========================================================================== commands
@FAST
@given(st.sampled_from(COMMANDS), st.lists(token, max_size=5))
def test_encoded_command_decodes_to_the_same_verb_and_arguments(verb, args):
    """encode_command -> decode_command keeps the verb and every argument token."""
    if len(" ".join([verb, *args])) > MAX_LINE:
        return
    line = encode_command(verb, *args)
    assert line.endswith(b"\n") and line.count(b"\n") == 1
    assert decode_command(line) == Command(verb, tuple(args))


def test_command_verb_is_case_insensitive_and_tolerates_crlf_and_spaces():
    """`conf  RATE 1000\\r\\n` is CONF with arguments RATE and 1000; only the verb is case-folded."""
    assert decode_command(b"conf  RATE 1000\r\n") == Command("CONF", ("RATE", "1000"))
    assert decode_command(b"Conf rate 1000") == Command("CONF", ("rate", "1000"))
    assert decode_command(b"idn?") == Command("IDN?", ())


@pytest.mark.parametrize(
    "line, problem",
    [
        (b"", "empty command line"),
        (b"   \r\n", "empty command line"),
        (b"FLY away\n", "unknown command 'FLY'"),
        (b"IDN\n", "unknown command 'IDN'"),
        (b"IDN?\x00\n", "not printable ASCII"),
        (b"CONF\tRATE 1\n", "not printable ASCII"),
        (b"CONF RATE \xff\n", "not printable ASCII"),
        (b"CONF " + b"x" * MAX_LINE + b"\n", "too long"),
    ],
)
def test_bad_commands_raise_a_protocol_error_that_names_the_problem(line, problem):
    """Empty, unknown, non-printable and over-long command lines are refused (answered ERR SYNTAX)."""
    with pytest.raises(ProtocolError, match=re.escape(problem)):
        decode_command(line)


@FUZZ
@given(
    st.one_of(
        st.binary(max_size=300),
        st.lists(
            st.sampled_from(
                [b"IDN?", b"conf", b"START", b" ", b"\r", b"\n", b"\x00", b"RATE", b"1000", b"\xff"]
            ),
            max_size=10,
        ).map(b"".join),
    )
)
def test_decode_command_gives_a_valid_command_or_a_protocol_error_for_any_bytes(line):
    """Any byte string: a known verb with printable, space-free arguments, or ProtocolError."""
    got = _outcome(decode_command, line)
    if isinstance(got, ProtocolError):
        assert str(got)
        return
    assert isinstance(got, Command)
    assert got.verb in COMMANDS
    for a in got.args:
        assert a and PRINTABLE.match(a) and " " not in a
    assert line.rstrip(b"\r\n").decode("ascii").split()[1:] == list(got.args)


# =========================================================================== the byte stream
@st.composite
def clean_streams(draw):
    """Frames and reply lines back to back, and the items they must decode to."""
    parts, want = [], []
    for _ in range(draw(st.integers(1, 8))):
        if draw(st.booleans()):
            seq, first, flags, codes = draw(small_frames)
            parts.append(encode_frame(seq, first, codes, flags))
            want.append(("frame", _expected_tuple(seq, first, flags, codes)))
        else:
            line, r = draw(reply_lines())
            parts.append(line)
            want.append(_item_key(r))
    return parts, want


@FAST
@given(clean_streams(), st.lists(st.integers(0, 10**6), max_size=12))
def test_stream_of_frames_and_replies_split_anywhere_decodes_exactly(stream, cuts):
    """Any split of a clean stream into reads gives exactly its frames and replies, in order, no error."""
    parts, want = stream
    data = b"".join(parts)
    d, items = _run_stream(_cut(data, cuts))
    assert [_item_key(i) for i in items] == want
    assert d.pos == len(d.buf), "bytes of a clean stream were left undecoded"


def test_stream_fed_one_byte_at_a_time():
    """Byte-by-byte reads (the worst split) still give every frame and reply."""
    f0 = encode_frame(
        0, 0, np.array([[0x5AA5, 0x0A4F]], dtype=np.uint16).view(np.int16)
    )  # sync + "O\n" in data
    f1 = encode_frame(1, 1, np.full((3, 2), -1, np.int16))
    data = b"OK START\r\n" + f0 + f1 + b"ERR STATE not streaming\n" + f0
    _, items = _run_stream([data[i : i + 1] for i in range(len(data))])
    kinds = [type(i).__name__ for i in items]
    assert kinds == ["Reply", "Frame", "Frame", "Reply", "Frame"]
    assert items[1].codes.view(np.uint16).tolist() == [[0x5AA5, 0x0A4F]]
    assert items[3].verb == "STATE" and items[3].text == "not streaming"


@FUZZ
@given(
    st.one_of(
        st.binary(max_size=600),
        st.lists(
            st.one_of(mutated_frames(), header_prefixed(), reply_like, st.binary(max_size=20)),
            max_size=6,
        ).map(b"".join),
    ),
    st.lists(st.integers(0, 10**6), max_size=8),
    st.none() | st.integers(1, 4),
    st.sampled_from([MAX_SETS, 1, 3, 6]),
)
def test_stream_decoder_on_any_bytes_yields_finitely_many_valid_items_and_only_moves_forward(
    data, cuts, expect, max_sets
):
    """Any bytes, any split: only Frames, Replies or ProtocolErrors, finitely many, position monotone.

    Each Frame is CRC-valid and is exactly the bytes just before the decoder's new position,
    each Reply ends at a newline it has consumed; splitting the input never invents an item
    (the chunked output is a prefix of the output for the whole input fed at once). The decoder
    never runs long without consuming input (``_ProgressGuard``).
    """
    d = StreamDecoder(expect, max_sets)
    fed, items = 0, []
    with _ProgressGuard(d):
        for chunk in _cut(data, cuts):
            d.feed(chunk)
            fed += len(chunk)
            before = d.offset + d.pos
            for item in itertools.islice(
                d.items(), fed + 1
            ):  # lazily: check the position after each item
                here = d.offset + d.pos
                assert before <= here <= fed
                if isinstance(item, Frame):
                    size = frame_size(item.n_sets, item.n_channels)
                    assert data[here - size : here] == encode_frame(
                        item.seq, item.first_sample, item.codes, item.flags
                    )
                    if expect is not None:
                        assert item.n_channels == expect
                    assert item.n_sets <= max_sets
                elif isinstance(item, Reply):
                    assert data[here - 1 : here] == b"\n"
                else:
                    assert isinstance(item, ProtocolError), type(item)
                    assert "stream offset" in str(item)
                items.append(item)
                before = here
            assert len(items) <= fed
    _, whole = _run_stream([data], expect, max_sets)
    chunked = [_item_key(i) for i in items]
    assert chunked == [_item_key(i) for i in whole][: len(chunked)]


# --------------------------------------------------------------------------- corruption and resync
#: After damage the decoder may have to wait for a false header's claimed length (at most one
#: 4096 x 32 frame) before it can reject it; a live device keeps streaming, modelled by this tail.
TAIL_BIG = encode_frame(1000, 10**6, np.zeros((MAX_SETS, MAX_CHANNELS), np.int16))
TAIL_SMALL = encode_frame(1001, 10**6 + MAX_SETS, np.arange(6, dtype=np.int16).reshape(3, 2))
TAIL = [TAIL_BIG, TAIL_SMALL]  # fed as two more reads
TAIL_KEYS = [
    ("frame", _frame_tuple(decode_frame(TAIL_BIG))),
    ("frame", _frame_tuple(decode_frame(TAIL_SMALL))),
]


@st.composite
def frame_lists(draw, min_size=0, max_size=3):
    out = []
    for _ in range(draw(st.integers(min_size, max_size))):
        seq, first, flags, codes = draw(small_frames)
        out.append(
            (
                encode_frame(seq, first, codes, flags),
                ("frame", _expected_tuple(seq, first, flags, codes)),
            )
        )
    return out


@SLOW
@given(frame_lists(), frame_args(max_sets=6, max_channels=4), frame_lists(min_size=1), st.data())
def test_one_corrupted_frame_gives_one_error_and_every_other_frame_is_decoded(
    before, bad, after, data
):
    """Flip any bit of one frame in a stream: one ProtocolError for it, all frames before and after decoded."""
    seq, first, flags, codes = bad
    b = bytearray(encode_frame(seq, first, codes, flags))
    bit = data.draw(st.integers(0, 8 * len(b) - 1), label="bit")
    b[bit // 8] ^= 1 << (bit % 8)
    stream = b"".join(f for f, _ in before) + bytes(b) + b"".join(f for f, _ in after)
    cuts = data.draw(st.lists(st.integers(0, len(stream)), max_size=4), label="cuts")
    _, items = _run_stream(_cut(stream, cuts) + TAIL)
    keys = [_item_key(i) for i in items]
    errors = [k for k in keys if k[0] == "error"]
    assert len(errors) == 1, keys
    assert keys == [k for _, k in before] + errors + [k for _, k in after] + TAIL_KEYS
    assert re.search(r"bad (CRC|sync|length)|unknown frame type|garbage", errors[0][1])


def test_corrupted_frame_in_the_middle_of_a_stream_reports_crc_and_offset():
    """A body bit flip (what simhw's 'corrupt' fault does) names the CRC and the stream offset."""
    frames = [encode_frame(i, 4 * i, np.full((4, 2), i, np.int16)) for i in range(3)]
    bad = bytearray(frames[1])
    bad[len(bad) // 2] ^= 0x10
    _, items = _run_stream([frames[0] + bytes(bad) + frames[2]])
    assert [type(i).__name__ for i in items] == ["Frame", "ProtocolError", "Frame"]
    assert [items[0].seq, items[2].seq] == [0, 2]
    assert str(items[1]).startswith("bad CRC in frame seq 1: computed")
    assert str(items[1]).endswith(f"(stream offset {len(frames[0])})")


@SLOW
@given(
    frame_lists(min_size=1),
    st.binary(min_size=1, max_size=200).filter(lambda g: b"\n" not in g),
    frame_lists(min_size=1),
    st.lists(st.integers(0, 10**6), max_size=4),
)
def test_garbage_between_frames_gives_one_error_and_the_later_frames_are_found(
    before, garbage, after, cuts
):
    """Any run of junk bytes (no newline) between frames: exactly one error, every frame decoded."""
    stream = b"".join(f for f, _ in before) + garbage + b"".join(f for f, _ in after)
    _, items = _run_stream(_cut(stream, cuts) + TAIL)
    keys = [_item_key(i) for i in items]
    errors = [k for k in keys if k[0] == "error"]
    assert len(errors) == 1, keys
    assert keys == [k for _, k in before] + errors + [k for _, k in after] + TAIL_KEYS
    assert f"(stream offset {sum(len(f) for f, _ in before)})" in errors[0][1]


@FAST
@given(
    st.binary(min_size=1, max_size=300).map(
        lambda g: bytes(x for x in g if x not in (0xA5, 0x4F, 0x45, 0x0A))
    ),
    frame_lists(min_size=1),
    st.lists(st.integers(0, 10**6), max_size=4),
)
def test_garbage_without_keyword_bytes_is_skipped_at_once(garbage, after, cuts):
    """Junk as simhw injects it (no 0xA5, 'O', 'E'): one error, the next frames decode with no tail."""
    if not garbage:
        garbage = b"\x00"
    stream = garbage + b"".join(f for f, _ in after)
    _, items = _run_stream(_cut(stream, cuts))
    keys = [_item_key(i) for i in items]
    assert keys[0][0] == "error" and keys[0][1].startswith(
        f"garbage: byte 0x{garbage[0]:02x} where a frame"
    )
    assert keys[1:] == [k for _, k in after]


def test_sync_or_keyword_split_by_a_read_right_after_garbage_is_not_lost():
    """Cut a garbage-laced stream at every byte (and feed it byte by byte): same items every time.

    After garbage the decoder skips ahead to the next sync pair or reply keyword; one that is
    cut in half by the end of a read (``\\xa5|\\x5a``, ``E|RR ``, ``O|K ``) must be kept, not skipped.
    """
    junk = b"\x00\x01\x02"
    f = encode_frame(4, 40, np.array([[1, -1]], np.int16))
    stream = (
        junk + f + junk + b"OK STOP samples=41\n" + junk + b"ERR STATE not streaming\r\n" + junk + f
    )
    want = [
        "ProtocolError",
        "Frame",
        "ProtocolError",
        "Reply",
        "ProtocolError",
        "Reply",
        "ProtocolError",
        "Frame",
    ]
    _, whole = _run_stream([stream])
    assert [type(i).__name__ for i in whole] == want
    keys = [_item_key(i) for i in whole]
    for cut in range(1, len(stream)):
        _, items = _run_stream([stream[:cut], stream[cut:]])
        assert [_item_key(i) for i in items] == keys, f"cut at byte {cut}"
    _, items = _run_stream([stream[i : i + 1] for i in range(len(stream))])
    assert [_item_key(i) for i in items] == keys


def test_long_garbage_run_gives_one_error_not_one_per_byte():
    """Ten kilobytes of junk, fed in small reads, are reported once."""
    rng = np.random.default_rng(1)
    junk = bytes(
        x
        for x in rng.integers(0, 256, 12000, dtype=np.uint8).tolist()
        if x not in (0xA5, 0x4F, 0x45)
    )
    good = encode_frame(9, 90, np.ones((2, 2), np.int16))
    stream = good + junk + good + b"OK STOP samples=92\n"
    _, items = _run_stream([stream[i : i + 100] for i in range(0, len(stream), 100)])
    assert [type(i).__name__ for i in items] == ["Frame", "ProtocolError", "Frame", "Reply"]
    assert items[3].fields == {"samples": "92"}


def test_bad_reply_line_in_the_stream_is_one_error_and_the_next_frame_is_decoded():
    """An unknown error code, then an over-long line: each one error; the frames around them decode."""
    good = encode_frame(1, 0, np.ones((1, 1), np.int16))
    stream = good + b"ERR WHAT\n" + good + b"OK " + b"z" * 300 + b"\n" + good
    _, items = _run_stream([stream])
    assert [type(i).__name__ for i in items] == [
        "Frame",
        "ProtocolError",
        "Frame",
        "ProtocolError",
        "Frame",
    ]
    assert "error code 'WHAT'" in str(items[1])
    assert "line longer than 256 bytes" in str(items[3])


def test_reply_line_of_max_length_in_the_stream_is_decoded():
    """256 bytes plus CR LF is still a line in the stream, not an over-long error."""
    line = b"OK X " + b"y" * (MAX_LINE - 5) + b"\r\n"
    _, items = _run_stream([line[:100], line[100:]])
    assert (
        len(items) == 1
        and isinstance(items[0], Reply)
        and items[0].words == ("y" * (MAX_LINE - 5),)
    )


def test_stream_error_kinds():
    """Errors from the stream carry a short `kind` (the message up to the first colon)."""
    good = encode_frame(1, 0, np.ones((1, 1), np.int16))
    _, items = _run_stream([b"\x00" + good + good[:3] + b"\x00" + good[4:] + good])
    assert [type(i).__name__ for i in items] == ["ProtocolError", "Frame", "ProtocolError", "Frame"]
    assert items[0].kind == "garbage"
    assert items[2].kind == "bad length"


def test_expect_channels_rejects_frames_of_another_width_and_keeps_the_rest():
    """With 2 channels configured, a 3-channel frame (valid CRC) is one error, not a frame."""
    two = encode_frame(0, 0, np.zeros((2, 2), np.int16))
    three = encode_frame(1, 2, np.zeros((2, 3), np.int16))
    _, items = _run_stream([two + three + two], expect_channels=2)
    assert [type(i).__name__ for i in items] == ["Frame", "ProtocolError", "Frame"]
    assert "frame carries 3 channels, 2 are configured" in str(items[1])


def test_decoder_discards_consumed_bytes_on_a_long_stream():
    """After more than 64 KiB the consumed prefix is dropped; offsets and frames stay right."""
    frame = encode_frame(0, 0, np.full((100, 8), 7, np.int16))
    d = StreamDecoder()
    n = 0
    with _ProgressGuard(d):
        for _ in range(100):
            d.feed(frame)
            n += len(list(itertools.islice(d.items(), 2)))
    assert n == 100
    assert d.offset > 0 and len(d.buf) <= (1 << 16) + 2 * len(frame)
    assert d.offset + d.pos == 100 * len(frame)


def test_length_field_beyond_the_configured_frame_is_rejected_at_once():
    """Configured for 2 channels x at most 4 sets, a set count flipped 4 -> 2052 fails at the header.

    So the next frame and the STOP reply come out at once instead of waiting for 8 KB of data.
    """
    f1 = encode_frame(0, 0, np.zeros((4, 2), np.int16))
    f2 = encode_frame(1, 4, np.ones((4, 2), np.int16))
    bad = bytearray(f1)
    bad[5] ^= 0x08
    _, items = _run_stream(
        [bytes(bad) + f2 + b"OK STOP samples=8\n"], expect_channels=2, max_sets=4
    )
    assert [type(i).__name__ for i in items] == ["ProtocolError", "Frame", "Reply"]
    assert str(items[0]).startswith("bad length: 2052 sample sets outside 1..4")
    assert items[1].seq == 1 and items[2].verb == "STOP"


def test_reply_after_a_short_frame_with_a_corrupted_length_field_is_not_held_back():
    """The last, short frame of a stream (2 of 10 sets) has its set count flipped 2 -> 10.

    The header passes (10 <= the configured 10 sets), so the decoder waits for
    10 x 8 x 2 + 24 = 184 bytes; only the 40-byte STOP reply follows, and the device then falls
    silent. The reader tells the decoder the line went quiet (``quiet()``), which gives the
    frame up and lets the reply out.
    """
    full = encode_frame(0, 0, np.zeros((10, 8), np.int16))
    bad = bytearray(encode_frame(1, 10, np.ones((2, 8), np.int16)))
    bad[4] ^= 0x08
    stop = b"OK STOP samples=12 frames=2 overruns=0\n"
    d, items = _run_stream([full + bytes(bad) + stop], expect_channels=8, max_sets=10)
    assert [type(i).__name__ for i in items] == ["Frame"]  # held back until the line goes quiet
    d.quiet()
    items += list(d.items())
    assert [type(i).__name__ for i in items] == ["Frame", "ProtocolError", "Reply"]
    assert "bad length" in str(items[1]) and items[2].fields["samples"] == "12"
    d.quiet()  # nothing held: nothing more to say
    assert list(d.items()) == []


# =========================================================================== merged runs
@st.composite
def frame_runs(draw):
    """Runs of frames that continue one another, broken where the device could break them: a
    lost frame, a sample jump, a flag, another shape, a corrupted byte, a reply or garbage; the
    sequence counter and the sample index near their wrap (the index must not wrap)."""
    parts = []
    seq = draw(st.one_of(seqs, st.integers(2**32 - 8, 2**32 - 1)))
    first = draw(st.one_of(st.integers(0, 2**40), st.integers(2**64 - 64, 2**64 - 1)))
    for _ in range(draw(st.integers(1, 5))):
        n, c = draw(st.integers(1, 4)), draw(st.integers(1, 3))
        for _ in range(draw(st.integers(1, 6))):
            codes = draw(hnp.arrays(np.int16, (n, c), elements=int16))
            flags = draw(st.sampled_from([0, 0, 0, 0, 0, FLAG_OVERRUN]))
            frame = bytearray(encode_frame(seq, first, codes, flags))
            if draw(st.integers(0, 9)) == 0:
                frame[draw(st.integers(0, len(frame) - 1))] ^= 1 << draw(st.integers(0, 7))
            parts.append(bytes(frame))
            seq = (seq + draw(st.sampled_from([1, 1, 1, 1, 1, 2]))) % 2**32
            first = (first + n * draw(st.sampled_from([1, 1, 1, 1, 1, 2]))) % 2**64  # wraps
        parts.append(draw(st.sampled_from([b"", b"", b"OK STAT samples=1\n", b"\x01\x02"])))
    return b"".join(parts)


def _frame_by_frame(items):
    """Merged frames cut back into the frames they stand for."""
    for item in items:
        if not isinstance(item, Frame) or item.frames == 1:
            yield item
            continue
        n = item.n_sets // item.frames
        for i in range(item.frames):
            yield Frame(
                (item.seq + i) % 2**32,
                item.first_sample + i * n,
                item.flags if i == 0 else 0,
                item.codes[i * n : (i + 1) * n],
            )


@FUZZ
@given(frame_runs(), st.lists(st.integers(0, 10**6), max_size=8), st.none() | st.integers(1, 3))
def test_merged_runs_are_the_frames_one_by_one(data, cuts, expect):
    """A decoder that merges runs gives the same frames (cut back), replies and errors, in the
    same order, for any split of any stream, and stops where frame-by-frame decoding stops."""
    chunks = _cut(data, cuts)
    one = StreamDecoder(expect)
    merged = StreamDecoder(expect, merge_runs=True)
    want, got = [], []
    for chunk in chunks:
        one.feed(chunk)
        merged.feed(chunk)
        want.extend(one.items())
        got.extend(merged.items())
        assert merged.offset + merged.pos == one.offset + one.pos
    assert [_item_key(i) for i in _frame_by_frame(got)] == [_item_key(i) for i in want]
    assert len(got) <= len(want)


def test_a_long_run_is_one_item():
    """A second of 10 ms frames at 200 Hz (two sets each) is one item of 200 sets, across the
    sequence counter's wrap."""
    codes = np.arange(400, dtype=np.int16).reshape(200, 2)
    d = StreamDecoder(2, 2, merge_runs=True)
    d.feed(encode_frames(2**32 - 3, 1000, codes, 2))
    (item,) = list(d.items())
    assert (item.seq, item.first_sample, item.frames) == (2**32 - 3, 1000, 100)
    assert np.array_equal(item.codes, codes)
