"""Fuzzed run files through the command line (issue 19 point 9, acceptance B).

Files are built with plain h5py from DESIGN.md section 6 (not with the project's writer), then
varied by hypothesis: layouts, dtypes, shapes, attributes and their encodings, lengths, lost
samples (NaN), events, truncation at a random byte offset. Each goes through ``fbs inspect``,
``fbs spectra``, ``fbs gap``, ``fbs analyze hysteresis`` and ``fbs recover`` (on a copy). Every
case must end with exit 0 and a correct result (the hysteresis figures of the model the file
was made from, the channels listed, a finite spectrum), or exit 2 with ``fbs <cmd>: error:``
and a message naming the problem - never a traceback. The fuzz calls ``fbs.cli.main`` in
process for speed; the paths that could hang (a FIFO given as the file, an external link to a
FIFO) and a few others run the real command in a subprocess whose timeout detects a hang (it
is not a timing assertion).
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import json
import math
import os
import shutil
import subprocess
import sys
import tempfile
from collections import Counter
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from drivers.rig_datasheet import RigCalibration
from fbs.cli import main
from procedures.analysis import dahl

# ---------------------------------------------------------------------------- the run the files hold
FS, F0 = 200.0, 1.0
TRUE_TO, TRUE_ETA = 0.012, 2.2e6
CHANNELS = ("cmd_x", "ac_x_inst", "pa_x")
GAP_CHANNELS = (
    "ac_x_inst",
    "pa_x",
)  # the model-gap workflow's of these (the command is its input, not compared)
LEAD = 200  # samples before the sweep (command at rest)
#: a hang detector for the subprocess cases (up to 17 at once), not a timing assertion
TIMEOUT_S = 300
MISSING = object()  # an attribute left out


def _sweep() -> dict[str, np.ndarray]:
    """The hysteresis sweep ``tests/procedures/test_hysteresis.write_sweep`` makes, small (13 s
    at 200 Hz, 3 amplitudes x 4 cycles at 1 Hz) and at the data sheet's constants: Dahl's model
    To = 0.012 N m, eta = 2.2e6 /N m on the default X platform."""
    cal = RigCalibration()
    p, ac = cal.platform["X"], cal.autocollimator["X"]
    n_per, cycles, updates = int(FS / F0), 4, 20
    amps = np.array([500.0, 150.0, 50.0]) * 1e-6
    t = np.arange(n_per * cycles * len(amps)) / FS
    amp = np.repeat(amps, n_per * cycles)
    lead = np.zeros(LEAD)
    smooth = np.concatenate([lead, amp * np.sin(2 * math.pi * F0 * t)])
    k = np.floor(t * F0 * updates)
    stair = np.concatenate([lead, amp * np.sin(2 * math.pi * (k + 0.5) / updates)])
    theta = smooth + 2e-3 * dahl.lowpass(stair - smooth, FS, 60.0)
    omega = np.gradient(theta) * FS
    alpha = np.gradient(omega) * FS
    torque = dahl.dahl_torque(theta, TRUE_TO, TRUE_ETA)
    noise = 1e-4 * np.random.default_rng(0).standard_normal(len(theta))
    pa = (
        torque + p.viscous_Nms * omega + p.inertia_kg_m2 * alpha + noise
    ) / p.torque_per_pa_V + 1e-4
    seen = dahl.shift(theta, FS, -2.5e-3)
    return {
        "cmd_x": -stair / 1e-6 * ac.control_mV_per_urad * 1e-3,
        "ac_x_inst": seen / 1e-6 * ac.inst_mV_per_urad * 1e-3 + 0.02,
        "pa_x": pa,
    }


SWEEP = _sweep()
N = len(SWEEP["pa_x"])
CALIBRATION = json.dumps(dataclasses.asdict(RigCalibration()))

# ---------------------------------------------------------------------------- what is varied
# (value, the words a refusal must contain, or None: the contract allows it)
FORMATS = [
    ("fbs-run", None),
    (b"fbs-run", None),
    (MISSING, "not an fbs-run file"),
    ("other", "not an fbs-run file"),
    (np.int64(1), "not an fbs-run file"),
]
VERSIONS = [
    (1, None),
    (np.int32(1), None),
    (1.0, None),
    (np.array([1]), None),
    (MISSING, "format_version"),
    (2, "format_version = 2"),
    (0, "format_version = 0"),
    ("1", "format_version"),
]
DTYPES = [
    ("<f8", None),
    ("<f4", None),
    (">f8", None),
    ("<f2", None),
    ("<i2", "int16 samples"),
    ("<i4", "int32 samples"),
    ("<u2", "uint16 samples"),
    ("<c16", "complex128 samples"),
    ("?", "bool samples"),
    ("S8", "S8 samples"),
]
UNITS = [
    ("V", None),
    (b"V", None),
    (["V"], None),
    (MISSING, "no units attribute"),
    (5, "units = 5"),
    (["V", "mV"], "not one value"),
    (b"\xff\xfe", "not UTF-8"),
]
RATES = [
    (FS, None),
    (int(FS), None),
    (np.float32(FS), None),
    (np.array([FS]), None),
    (MISSING, "no sample_rate_hz"),
    (math.inf, "not finite"),
    (math.nan, "not finite"),
    (0.0, "not positive"),
    (-FS, "not positive"),
    (1e-300, "outside the 0.001 .. 1e+07 Hz"),
    (1e300, "outside the 0.001 .. 1e+07 Hz"),
    ("200", "not a number"),
    (True, "not a number"),
    (2 * FS, "different sample rates"),
]
OTHER_RATE = len(RATES) - 1  # one channel at another (valid) rate than the rest
# layouts of /channels; the first words a refusal names. "alias" adds a soft link to a channel (allowed).
LAYOUTS = [
    ("normal", None),
    ("alias", None),
    ("extra_group", "a group, not a 1-D dataset"),
    ("extra_2d", "2-D (shape (4, 3))"),
    ("extra_scalar", "0-D"),
    ("dangling", "does not exist"),
    ("external", "another file"),
    ("no_channels", "has no /channels group"),
    ("channels_dataset", "/channels is a Dataset"),
    ("empty", "has no channels"),
]
LENGTHS = [("equal", None), ("short", "different lengths"), ("zero", "holds no samples")]
EVENTS = [
    ("none", None),
    ("ok", None),
    ("group", "/events is a Group"),
    ("no_fields", "/events lacks"),
]
NAN_WHERE = {
    "lead": slice(20, 40),
    "cycles": slice(1200, 1210),
    "end": slice(N - 5, N),
    "all": slice(0, N),
}


@dataclasses.dataclass(frozen=True)
class Case:
    libver: str
    fmt: int
    version: int
    layout: int
    dtype: int
    dtype_on: str  # a channel, or "all"
    units: int
    units_on: str
    rate: int
    rate_on: str
    lengths: int
    events: int
    nan: tuple[str, str] | None
    axis: bool
    calibration: bool
    extra_group: bool
    cut: float | None  # truncate to this fraction of the file's bytes

    def problems(self) -> list[str]:
        """The words the refusal names, in the order the reader checks (empty: a valid file)."""
        if FORMATS[self.fmt][1]:
            return [str(FORMATS[self.fmt][1])]
        if VERSIONS[self.version][1] and VERSIONS[self.version][0] is not MISSING:
            return [str(VERSIONS[self.version][1])]
        out = [str(VERSIONS[self.version][1])] if VERSIONS[self.version][1] else []
        layout = LAYOUTS[self.layout]
        if layout[0] in ("no_channels", "channels_dataset", "empty"):
            return [*out, str(layout[1])]
        if layout[1]:
            out.append(str(layout[1]))
        for table, i in ((DTYPES, self.dtype), (UNITS, self.units), (RATES, self.rate)):
            if table[i][1]:
                out.append(str(table[i][1]))
        if LENGTHS[self.lengths][1]:
            out.append(str(LENGTHS[self.lengths][1]))
        if EVENTS[self.events][1]:
            out.append(str(EVENTS[self.events][1]))
        return out


ON = st.sampled_from(("all", *CHANNELS))


@st.composite
def cases(draw: st.DrawFn) -> Case:
    """Mostly one thing wrong at a time (a third of the cases valid), sometimes several."""
    n_wrong = (0, 0, 0, 0, 1, 1, 1, 1, 1, 2)[draw(st.integers(0, 9))]
    knobs = draw(
        st.lists(
            st.sampled_from(
                ("fmt", "version", "layout", "dtype", "units", "rate", "lengths", "events", "cut")
            ),
            min_size=n_wrong,
            max_size=n_wrong,
            unique=True,
        )
    )

    def pick(name: str, table: list) -> int:
        ok = [i for i, row in enumerate(table) if row[1] is None]
        bad = [i for i, row in enumerate(table) if row[1] is not None]
        return draw(st.sampled_from(bad if name in knobs else ok))

    nan = draw(
        st.one_of(
            st.none(),
            st.none(),
            st.tuples(st.sampled_from(CHANNELS), st.sampled_from(tuple(NAN_WHERE))),
        )
    )
    return Case(
        libver=draw(st.sampled_from(("earliest", "v110"))),
        fmt=pick("fmt", FORMATS),
        version=pick("version", VERSIONS),
        layout=pick("layout", LAYOUTS),
        dtype=pick("dtype", DTYPES),
        dtype_on=draw(ON),
        units=pick("units", UNITS),
        units_on=draw(ON),
        rate=pick("rate", RATES),
        rate_on=draw(ON) if "rate" in knobs else "all",
        lengths=pick("lengths", LENGTHS),
        events=pick("events", EVENTS),
        nan=nan,
        axis=draw(st.booleans()),
        calibration=draw(st.booleans()),
        extra_group=draw(st.booleans()),
        cut=draw(st.floats(0.0, 0.999)) if "cut" in knobs else None,
    )


def _set(attrs: Any, name: str, value: Any) -> None:
    if value is not MISSING:
        attrs[name] = value


def build(path: Path, case: Case) -> Path:
    """The file of ``case``, with plain h5py, as DESIGN.md section 6 lays it out."""
    with h5py.File(path, "w", libver=case.libver) as f:
        _set(f.attrs, "format", FORMATS[case.fmt][0])
        _set(f.attrs, "format_version", VERSIONS[case.version][0])
        f.attrs.update(
            {"created": "1974-06-01T00:00:00Z", "rig": "fuzz", "mode": 3, "status": "complete"}
        )
        if case.axis:
            f.attrs["axis"] = "X"
        layout = LAYOUTS[case.layout][0]
        if layout == "channels_dataset":
            f.create_dataset("channels", data=np.zeros((N, 3)))
        elif layout == "empty":
            f.create_group("channels")
        elif layout != "no_channels":
            g = f.create_group("channels")
            n = {"equal": N, "short": N, "zero": 0}[LENGTHS[case.lengths][0]]
            for c in CHANNELS:
                x = SWEEP[c][:n].copy()
                if case.nan and case.nan[0] == c:
                    x[NAN_WHERE[case.nan[1]]] = np.nan
                if LENGTHS[case.lengths][0] == "short" and c == "pa_x":
                    x = x[:-10]
                dtype = DTYPES[case.dtype][0] if case.dtype_on in ("all", c) else "<f8"
                with np.errstate(invalid="ignore", over="ignore"):
                    data = (
                        np.nan_to_num(x * 1000).astype(dtype)
                        if np.dtype(dtype).kind in "iub"
                        else x.astype(dtype)
                    )
                ds = g.create_dataset(c, data=data, chunks=(512,) if n else None, maxshape=(None,))
                _set(
                    ds.attrs, "units", UNITS[case.units][0] if case.units_on in ("all", c) else "V"
                )
                rate = RATES[case.rate][0]
                if (
                    case.rate == OTHER_RATE
                ):  # pa_x, or the channel drawn, at another rate than the rest
                    rate = (
                        2 * FS if c == (case.rate_on if case.rate_on != "all" else "pa_x") else FS
                    )
                elif case.rate_on not in ("all", c):
                    rate = FS
                _set(ds.attrs, "sample_rate_hz", rate)
            if layout == "alias":
                g["pa_x_alias"] = h5py.SoftLink("/channels/pa_x")
            elif layout == "extra_group":
                g.create_group("zz")
            elif layout == "extra_2d":
                g.create_dataset("zz", data=np.zeros((4, 3)))
            elif layout == "extra_scalar":
                g.create_dataset("zz", data=1.0)
            elif layout == "dangling":
                g["zz"] = h5py.SoftLink("/nowhere")
            elif layout == "external":
                g["zz"] = h5py.ExternalLink(str(path.with_name("other.h5")), "/x")
        events = EVENTS[case.events][0]
        if events == "ok":
            f.create_dataset(
                "events",
                data=np.array(
                    [(0.0, b"mode", b"mode 3"), (6.0, b"gap", b"ADC samples 1200..1209 lost")],
                    dtype=[("time", "f8"), ("kind", "S32"), ("text", "S1024")],
                ),
                maxshape=(None,),
            )
        elif events == "group":
            f.create_group("events")
        elif events == "no_fields":
            f.create_dataset("events", data=np.arange(3.0))
        if case.calibration:
            f.create_group("meta").attrs["calibration"] = CALIBRATION
        if case.extra_group:
            f.create_group("lab_notes").attrs["by"] = "another writer"  # extra groups are allowed
    if case.cut is not None:
        raw = path.read_bytes()
        path.write_bytes(raw[: int(case.cut * len(raw))])
    return path


# ---------------------------------------------------------------------------- running the commands
STATS: Counter[str] = Counter()


def run(argv: list[str]) -> tuple[int, str, str]:
    """``fbs argv`` in this process: (exit code, stdout, stderr). An exception escaping ``main``
    would be a traceback: the test fails with it. The streams encode strictly to UTF-8, as a
    terminal's do: text that cannot be printed (undecodable bytes from the file) fails here too."""
    out, err = (io.TextIOWrapper(io.BytesIO(), encoding="utf-8", errors="strict") for _ in range(2))
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(argv)
    out.flush()
    err.flush()
    text_out, text_err = (s.buffer.getvalue().decode("utf-8") for s in (out, err))  # type: ignore[attr-defined]
    STATS[f"{argv[0] if argv[0] != 'analyze' else 'hysteresis'} exit {code}"] += 1
    assert "Traceback" not in text_err, text_err
    return code, text_out, text_err


def refused(cmd: str, code: int, err: str, words: list[str]) -> None:
    """Exit 2 with ``fbs <cmd>: error:`` naming every one of ``words``."""
    assert code == 2, err
    assert f"fbs {cmd}: error:" in err, err
    for w in words:
        assert w in err, f"{w!r} not in {err!r}"


TRUNCATED = ("truncated", "not an HDF5 file", "cannot open")


def check_case(tmp: Path, case: Case) -> None:
    path = build(tmp / "run.h5", case)
    problems = case.problems()
    cut = case.cut is not None
    valid = not problems and not cut
    # inspect: the file described, or refused naming the rule (a broken file still shown on stdout)
    code, out, err = run(["inspect", str(path)])
    if valid:
        assert code == 0, err
        for c in CHANNELS:
            assert c in out
        assert f"rate {FS:g} Hz, {N} samples" in out
    elif cut:
        assert code == 2 and any(w in err for w in TRUNCATED), err
    else:
        refused("inspect", code, err, problems)
        assert "breaks the layout contract" in out
    # spectra of the channel that lost samples (or pa_x): skipped segments are counted, never spliced
    ch = case.nan[0] if case.nan else "pa_x"
    code, out, err = run(["spectra", str(path), "--channels", ch, "--out", str(tmp / "spectra")])
    if valid and not (case.nan and case.nan[1] == "all"):
        assert code == 0, err
        table = np.loadtxt(tmp / "spectra" / "spectra.csv", delimiter=",", skiprows=1)
        assert table.shape[1] == 2 and np.isfinite(table).all() and table[1:, 1].max() > 0
        if case.nan is None:
            assert "none skipped" in out
        elif case.nan[1] in ("lead", "cycles"):
            assert "skipped (lost samples)" in out
    elif valid:
        refused("spectra", code, err, ["lost samples (NaN)", f"{ch} has {N} lost", "`gap` event"])
    elif cut:
        assert code == 2 and any(w in err for w in TRUNCATED), err
    else:
        refused("spectra", code, err, problems)
    # gap: these 13 s are too short for it, but lost samples are named before that
    code, out, err = run(["gap", str(path), "--axis", "X"])
    if valid and case.nan and case.nan[0] in GAP_CHANNELS:
        refused(
            "gap",
            code,
            err,
            [f"channel {case.nan[0]} has", "lost (NaN) samples: samples", "`gap` event"],
        )
    elif valid:
        refused("gap", code, err, ["record too short"])
    elif cut:
        assert code == 2 and any(w in err for w in TRUNCATED), err
    else:
        refused("gap", code, err, problems)
    # analyze hysteresis: Dahl's To of the model, or lost samples in the cycles named
    code, out, err = run(["analyze", "hysteresis", str(path), "--axis", "X", "--json"])
    lost_words = [f"{case.nan[0]} has", "lost (NaN) samples", "`gap` event"] if case.nan else []
    if valid and case.nan and case.nan[1] == "end" and code == 2:
        refused(
            "analyze", code, err, lost_words
        )  # the last cycle's command cut: in the cycles, or not
    elif valid and (case.nan is None or case.nan[1] in ("lead", "end")):
        assert code == 0, err
        res = json.loads(out)
        tol = 0.05 if DTYPES[case.dtype][0] == "<f2" else 0.01
        To, eta = res["To_Nm"]["X"], res["eta_per_Nm"]["X"]  # per axis (issue 37)
        assert To == pytest.approx(TRUE_TO, rel=tol)
        assert eta == pytest.approx(TRUE_ETA, rel=5 * tol)
    elif valid and case.nan[1] == "cycles" and code == 0:
        # analysed around the lost samples (issue 36 item 2): the cycles near them left out, said so
        assert "analysed around" in err, err
        res = json.loads(out)
        tol = 0.15 if DTYPES[case.dtype][0] == "<f2" else 0.03
        To, eta = res["To_Nm"]["X"], res["eta_per_Nm"]["X"]  # per axis (issue 37)
        assert To == pytest.approx(TRUE_TO, rel=tol)
        assert eta == pytest.approx(TRUE_ETA, rel=5 * tol)
    elif valid:
        refused("analyze", code, err, lost_words)
    elif cut:
        assert code == 2 and any(w in err for w in TRUNCATED), err
    else:
        refused("analyze", code, err, problems)
    # recover, on a copy: any outcome but a traceback; a file only its lengths broke is repaired
    if cut and path.stat().st_size < 48:
        return  # inside the superblock: test_recover_on_a_cut_superblock_is_refused
    copy = tmp / "copy.h5"
    shutil.copyfile(path, copy)
    code, out, err = run(["recover", str(copy)])
    assert code in (0, 2), err
    if code == 2:
        assert "fbs recover: error:" in err
    if problems == ["different lengths"] and case.libver == "v110":
        assert code == 0, err
        code, out, err = run(["inspect", str(copy)])
        assert code == 0 and f"rate {FS:g} Hz, {N} samples" in out, err


#: a valid file: every table's first row, no lost samples
VALID = Case("earliest", 0, 0, 0, 0, "all", 0, "all", 0, "all", 0, 0, None, True, True, False, None)


def _explicit_cases() -> list[Case]:
    """Every rule broken alone (each bad row of each table, on one channel or all), each valid
    encoding, lost samples in each place, and cuts: hypothesis's draws then combine them."""
    out = []
    tables = (
        ("fmt", FORMATS),
        ("version", VERSIONS),
        ("layout", LAYOUTS),
        ("dtype", DTYPES),
        ("units", UNITS),
        ("rate", RATES),
        ("lengths", LENGTHS),
        ("events", EVENTS),
    )
    for k, (name, table) in enumerate(tables):
        for i, row in enumerate(table):
            if row[1] is not None:
                on = (
                    {f"{name}_on": CHANNELS[(i + k) % 3]}
                    if name in ("dtype", "units", "rate") and i % 2
                    else {}
                )
                out.append(
                    dataclasses.replace(
                        VALID, libver=("earliest", "v110")[i % 2], **{name: i}, **on
                    )
                )
    # the valid encodings, several to a file
    out += [
        Case(
            "v110",
            1,
            1,
            1,
            1,
            "all",
            1,
            "all",
            1,
            "all",
            0,
            1,
            ("pa_x", "lead"),
            False,
            False,
            True,
            None,
        ),
        Case(
            "earliest",
            0,
            2,
            0,
            2,
            "pa_x",
            2,
            "all",
            2,
            "all",
            0,
            0,
            ("ac_x_inst", "end"),
            True,
            True,
            False,
            None,
        ),
        Case(
            "v110",
            0,
            3,
            1,
            3,
            "ac_x_inst",
            1,
            "cmd_x",
            3,
            "all",
            0,
            1,
            ("cmd_x", "lead"),
            True,
            True,
            True,
            None,
        ),
    ]
    out += [
        dataclasses.replace(VALID, nan=nan)
        for nan in (
            ("pa_x", "cycles"),
            ("cmd_x", "cycles"),
            ("ac_x_inst", "all"),
            ("cmd_x", "all"),
            ("pa_x", "end"),
        )
    ]
    out += [
        dataclasses.replace(VALID, libver=lib, cut=cut)
        for lib in ("earliest", "v110")
        for cut in (0.0, 0.003, 0.02, 0.2, 0.5, 0.9, 0.999)
    ]
    return out


def _with_examples(test: Any) -> Any:
    for case in _explicit_cases():
        test = example(case=case)(test)
    return test


@settings(
    max_examples=40,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
@_with_examples
@given(case=cases())
def test_fuzzed_files_end_in_a_result_or_a_named_refusal(case: Case) -> None:
    STATS["cases"] += 1
    STATS["valid" if not case.problems() and case.cut is None else "broken"] += 1
    for p in case.problems() + (["truncated"] if case.cut is not None else []):
        STATS[f"rule: {p}"] += 1
    if case.nan:
        STATS[f"NaN: {case.nan[1]}"] += 1
    with tempfile.TemporaryDirectory() as d:
        check_case(Path(d), case)


def test_zz_fuzz_statistics(capsys: pytest.CaptureFixture[str]) -> None:
    """How the fuzz above went (shown with ``-s`` or on failure): cases, exits per command."""
    with capsys.disabled():
        print("\nfuzz statistics:", dict(sorted(STATS.items())))


# ---------------------------------------------------------------------------- explicit cases
def test_the_issue_cases_are_refused_naming_the_rule(tmp_path: Path) -> None:
    """Issue 19 point 9: int16 counts read as volts gave To = 52 N m; sample_rate_hz inf or
    1e-300 and format_version 2 were analysed; a group for a channel was a traceback."""
    base = VALID
    for changes, words in (
        ({"dtype": 4}, ["int16 samples", "integer ADC counts are not volts", "cmd_x"]),
        ({"rate": 5}, ["sample_rate_hz = inf is not finite"]),
        ({"rate": 9}, ["sample_rate_hz = 1e-300 Hz is outside the 0.001 .. 1e+07 Hz"]),
        ({"version": 5}, ["format_version = 2", "reads fbs-run version 1 only"]),
        ({"layout": 2}, ["/channels/zz: a group, not a 1-D dataset"]),
    ):
        case = dataclasses.replace(base, **changes)
        path = build(tmp_path / "run.h5", case)
        for argv in (
            ["analyze", "hysteresis", str(path), "--json"],
            ["spectra", str(path), "--channels", "pa_x"],
            ["gap", str(path)],
            ["inspect", str(path)],
        ):
            code, out, err = run(argv)
            refused(argv[0], code, err, words)
            assert out == "" or argv[0] == "inspect"


def test_gap_on_lost_samples_names_them_instead_of_a_result(tmp_path: Path) -> None:
    base = Case(
        "v110",
        0,
        0,
        0,
        0,
        "all",
        0,
        "all",
        0,
        "all",
        0,
        1,
        ("ac_x_inst", "cycles"),
        True,
        True,
        False,
        None,
    )
    path = build(tmp_path / "run.h5", base)
    code, out, err = run(["gap", str(path), "--json"])
    refused(
        "gap",
        code,
        err,
        [
            "channel ac_x_inst has 10 lost (NaN) samples",
            "samples 1200..1209 (6.000..6.045 s)",
            "`gap` event",
        ],
    )
    assert out == ""


def _spawn(argv: list[str]) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "fbs", *argv],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=Path(__file__).parents[2],
    )


def _finish(p: subprocess.Popen[str]) -> tuple[int, str, str]:
    try:
        out, err = p.communicate(timeout=TIMEOUT_S)
    except subprocess.TimeoutExpired:
        p.kill()
        p.communicate()
        pytest.fail(f"fbs {' '.join(map(str, p.args))} hung (no exit in {TIMEOUT_S} s)")
    assert "Traceback" not in err, err
    return p.returncode, out, err


ALL_COMMANDS = (
    ["inspect"],
    ["spectra", "--channels", "pa_x"],
    ["gap"],
    ["analyze", "hysteresis"],
    ["recover"],
)


def _argv(cmd: list[str], path: Path) -> list[str]:
    return [*cmd[:2], str(path), *cmd[2:]] if cmd[0] == "analyze" else [cmd[0], str(path), *cmd[1:]]


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs on this system")
def test_a_fifo_a_directory_and_links_to_a_fifo_are_refused_without_hanging(tmp_path: Path) -> None:
    """In subprocesses, so that a command that opened the FIFO (and waited forever for a writer)
    fails the test on the timeout instead of hanging the suite."""
    fifo = tmp_path / "pipe.h5"
    os.mkfifo(fifo)
    folder = tmp_path / "folder.h5"
    folder.mkdir()
    linked = tmp_path / "linked.h5"
    with h5py.File(linked, "w") as f:
        f.attrs.update({"format": "fbs-run", "format_version": 1})
        g = f.create_group("channels")
        ds = g.create_dataset("cmd_x", data=SWEEP["cmd_x"])
        ds.attrs.update({"units": "V", "sample_rate_hz": FS})
        g["pa_x"] = h5py.ExternalLink(str(fifo), "/x")
    root_linked = tmp_path / "root_linked.h5"
    with h5py.File(root_linked, "w") as f:
        f.attrs.update({"format": "fbs-run", "format_version": 1})
        f["channels"] = h5py.ExternalLink(str(fifo), "/channels")
    counts = build(
        tmp_path / "counts.h5",
        Case(
            "earliest", 0, 0, 0, 4, "all", 0, "all", 0, "all", 0, 0, None, True, True, False, None
        ),
    )
    jobs = [
        (
            cmd,
            fifo,
            "is a FIFO (named pipe), not a run file"
            if cmd[0] != "recover"
            else "not a regular file",
        )
        for cmd in ALL_COMMANDS
    ]
    jobs += [
        (cmd, folder, "is a directory" if cmd[0] != "recover" else "not a regular file")
        for cmd in ALL_COMMANDS
    ]
    jobs += [(cmd, linked, "/channels/pa_x: a link to") for cmd in ALL_COMMANDS[:4]]
    jobs += [
        (["inspect"], root_linked, "/channels is a link to"),
        (["analyze", "hysteresis"], root_linked, "/channels is a link to"),
        (["analyze", "hysteresis"], counts, "int16 samples"),
    ]
    procs = [(_spawn(_argv(cmd, path)), cmd, words) for cmd, path, words in jobs]
    try:
        for p, cmd, words in procs:
            code, _out, err = _finish(p)
            assert code == 2 and f"fbs {cmd[0]}: error:" in err and words in err, (cmd, err)
    finally:  # a failure above must not leave the others waiting on the FIFO for ever
        for p, _cmd, _words in procs:
            with p:  # its pipes closed and the process reaped, however it ended
                if p.poll() is None:
                    p.kill()
    assert fifo.exists() and folder.is_dir()


# ---------------------------------------------------------------------------- found by the fuzz
@pytest.mark.parametrize("size", [8, 9, 10])
def test_recover_on_a_cut_superblock_is_refused(tmp_path: Path, size: int) -> None:
    path = tmp_path / "cut.h5"
    with h5py.File(path, "w", libver="v110") as f:
        f.create_dataset("channels/a", data=np.zeros(4))
    path.write_bytes(path.read_bytes()[:size])
    code, _out, err = run(["recover", str(path)])
    assert code == 2 and "fbs recover: error:" in err and "superblock" in err, err


def test_recover_refuses_an_external_link_to_a_fifo_without_following_it(tmp_path: Path) -> None:
    fifo = tmp_path / "pipe.h5"
    os.mkfifo(fifo)
    path = tmp_path / "linked.h5"
    with h5py.File(path, "w", libver="v110") as f:
        f.attrs.update({"format": "fbs-run", "format_version": 1})
        ds = f.create_dataset("channels/a", data=np.zeros(10))
        ds.attrs.update({"units": "V", "sample_rate_hz": 10.0})
        f["channels/b"] = h5py.ExternalLink(str(fifo), "/x")
    code, _out, err = _finish(_spawn(["recover", str(path)]))
    assert code == 2 and "fbs recover: error:" in err and "another file" in err, err
