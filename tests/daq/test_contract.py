"""The "fbs-run" version 1 layout contract (DESIGN.md section 6), checked when a run file is
opened for analysis (``daq.reader.RunFile``): one test per rule, each on a file made with plain
h5py that breaks it, and the refusal names the rule and the bad value (issue 19 point 9)."""

from __future__ import annotations

import math
import os
import subprocess
import sys
import textwrap
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pytest

from daq.contract import MAX_RATE_HZ, MIN_RATE_HZ, READABLE_VERSIONS, ContractError
from daq.reader import (
    RunFile,
    UnreadableRunFile,
    lost_samples,
    nonfinite_spans,
)
from daq.runfile import RunFileError, RunWriter

FS = 100.0


def write(
    path: Path,
    *,
    root: dict[str, Any] | None = None,
    channels: dict[str, Any] | None = None,
    attrs: dict[str, dict[str, Any]] | None = None,
    drop: tuple[str, ...] = (),
    libver: str = "earliest",
    events: Any = None,
) -> Path:
    """A contract file with channels a and b (100 samples each, 100 Hz, volts) from plain h5py;
    ``root``/``attrs`` override attributes (None deletes one), ``channels`` replaces datasets'
    data (a value that is not an array is stored as is: a group, a link)."""
    data: dict[str, Any] = {"a": np.linspace(0, 1, 100), "b": np.linspace(1, 2, 100)}
    data.update(channels or {})
    with h5py.File(path, "w", libver=libver) as f:
        base = {
            "format": "fbs-run",
            "format_version": 1,
            "created": "1974-06-01T00:00:00Z",
            "rig": "FBS",
            "mode": 3,
        }
        for k, v in {**base, **(root or {})}.items():
            if v is not None:
                f.attrs[k] = v
        if "channels" not in drop:
            g = f.create_group("channels")
            for name, x in data.items():
                if isinstance(x, np.ndarray):
                    ds = g.create_dataset(name, data=x)
                    for k, v in {
                        "units": "V",
                        "sample_rate_hz": FS,
                        **(attrs or {}).get(name, {}),
                    }.items():
                        if v is not None:
                            ds.attrs[k] = v
                elif x == "group":
                    g.create_group(name)
                else:
                    g[name] = x
        if events is not None:
            f["events"] = events
    return path


def refused(path: Path, *words: str, error: type[RunFileError] = ContractError) -> str:
    with pytest.raises(error) as info:
        RunFile(path)
    msg = str(info.value)
    for w in words:
        assert w in msg, f"{w!r} not in {msg!r}"
    return msg


# ---------------------------------------------------------------------------- files that follow it
def test_a_minimal_file_of_any_writer_opens(tmp_path: Path) -> None:
    p = write(
        tmp_path / "ok.h5",
        channels={"a": np.zeros(100, dtype="<f4"), "b": np.zeros(100, dtype=">f8")},
        attrs={
            "a": {"units": b"V", "sample_rate_hz": np.float32(FS)},
            "b": {"sample_rate_hz": 100},
        },
        root={"format": b"fbs-run", "format_version": np.int32(1)},
    )
    with RunFile(p) as run:
        assert (
            run.channels == ("a", "b") and run.rate_hz == FS and run.units == {"a": "V", "b": "V"}
        )
        assert run.read().dtype == np.float64 and run.n_samples == 100


def test_extra_groups_soft_links_and_one_element_attributes_are_allowed(tmp_path: Path) -> None:
    p = write(
        tmp_path / "ok.h5",
        channels={"alias": h5py.SoftLink("/channels/a")},
        attrs={"a": {"units": ["V"], "sample_rate_hz": np.array([FS])}},
        root={"format_version": 1.0},
    )
    with h5py.File(p, "a") as f:
        f.create_group("lab_notes").attrs["by"] = "someone else"
    with RunFile(p) as run:
        assert run.channels == ("a", "alias", "b") and run.units["a"] == "V"


def test_opening_reads_no_sample(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The checks are attributes, types and shapes: cheap on a file of any size."""
    p = write(tmp_path / "ok.h5")

    def no(*_args: Any, **_kw: Any) -> None:
        raise AssertionError("a sample was read while opening")

    monkeypatch.setattr(h5py.Dataset, "__getitem__", no)
    monkeypatch.setattr(h5py.Dataset, "read_direct", no)
    with RunFile(p) as run:
        assert run.n_samples == 100


# ---------------------------------------------------------------------------- rule 1: a regular file
@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs here")
def test_a_fifo_is_refused_without_opening_it(tmp_path: Path) -> None:
    """In a child: opening the FIFO would wait for a writer for ever (the test's timeout)."""
    fifo = tmp_path / "pipe.h5"
    os.mkfifo(fifo)
    code = textwrap.dedent("""
        import sys
        from daq.reader import RunFile, UnreadableRunFile
        try:
            RunFile(sys.argv[1])
        except UnreadableRunFile as exc:
            print(exc)
    """)
    p = subprocess.run(
        [sys.executable, "-c", code, str(fifo)], capture_output=True, text=True, timeout=60
    )
    assert p.returncode == 0 and "is a FIFO (named pipe), not a run file" in p.stdout, p.stderr


def test_a_directory_and_a_device_are_refused(tmp_path: Path) -> None:
    (tmp_path / "d.h5").mkdir()
    refused(tmp_path / "d.h5", "is a directory, not a run file", error=UnreadableRunFile)
    if Path("/dev/null").exists():
        refused(Path("/dev/null"), "is a character device", error=UnreadableRunFile)
    refused(tmp_path / "missing.h5", "no such file", error=UnreadableRunFile)


# ---------------------------------------------------------------------------- rule 2: HDF5, whole, readable
def test_not_hdf5_and_empty_files_are_named(tmp_path: Path) -> None:
    (tmp_path / "t.h5").write_text("time,gyro_x\n0,1\n")
    refused(tmp_path / "t.h5", "is not an HDF5 file (no HDF5 signature", error=UnreadableRunFile)
    (tmp_path / "e.h5").write_bytes(b"")
    refused(tmp_path / "e.h5", "e.h5", error=UnreadableRunFile)


def test_a_truncated_file_says_how_much_is_missing(tmp_path: Path) -> None:
    p = write(tmp_path / "t.h5", libver="v110")
    raw = p.read_bytes()
    p.write_bytes(raw[: len(raw) // 2])
    refused(
        p,
        "is truncated",
        f"{len(raw) // 2} bytes on disk",
        f"records {len(raw)}",
        error=UnreadableRunFile,
    )


# ---------------------------------------------------------------------------- rule 3: format and version
def test_format_must_be_fbs_run(tmp_path: Path) -> None:
    refused(
        write(tmp_path / "o.h5", root={"format": "other"}),
        "is not an fbs-run file (format = 'other')",
    )
    refused(
        write(tmp_path / "m.h5", root={"format": None}),
        "is not an fbs-run file (no root attribute format",
    )


@pytest.mark.parametrize(
    "version, shown",
    [
        (2, "format_version = 2"),
        (0, "format_version = 0"),
        ("1", "format_version = '1' is not a number"),
        (None, "no root attribute format_version"),
    ],
)
def test_format_version_must_be_one_this_reader_reads(
    tmp_path: Path, version: Any, shown: str
) -> None:
    assert READABLE_VERSIONS == (1,)
    refused(
        write(tmp_path / "v.h5", root={"format_version": version}), shown, "reads fbs-run version 1"
    )


def test_another_version_is_refused_before_its_layout_is_judged(tmp_path: Path) -> None:
    msg = refused(
        write(tmp_path / "v.h5", root={"format_version": 2}, drop=("channels",)),
        "format_version = 2",
    )
    assert "/channels" not in msg


# ---------------------------------------------------------------------------- rule 4: /channels, 1-D datasets
def test_channels_must_be_a_group_of_datasets(tmp_path: Path) -> None:
    refused(write(tmp_path / "n.h5", drop=("channels",)), "has no /channels group")
    with h5py.File(tmp_path / "d.h5", "w") as f:
        f.attrs.update({"format": "fbs-run", "format_version": 1})
        f["channels"] = np.zeros((100, 2))
    refused(tmp_path / "d.h5", "/channels is a Dataset, not a group")
    with h5py.File(tmp_path / "e.h5", "w") as f:
        f.attrs.update({"format": "fbs-run", "format_version": 1})
        f.create_group("channels")
    refused(tmp_path / "e.h5", "has no channels")


@pytest.mark.parametrize(
    "member, words",
    [
        ("group", "/channels/x: a group, not a 1-D dataset"),
        (np.zeros((100, 2)), "/channels/x: 2-D (shape (100, 2)): a channel is a 1-D dataset"),
        (np.float64(1.0), "/channels/x: 0-D"),
        (h5py.SoftLink("/nowhere"), "/channels/x: a link to /nowhere, which does not exist"),
        (h5py.ExternalLink("other.h5", "/x"), "/channels/x: a link to other.h5:/x (another file)"),
    ],
)
def test_every_member_of_channels_is_a_1d_dataset_in_the_file(
    tmp_path: Path, member: Any, words: str
) -> None:
    if isinstance(member, np.generic):
        p = write(tmp_path / "m.h5")
        with h5py.File(p, "a") as f:
            f["channels"].create_dataset("x", data=member)
    else:
        p = write(tmp_path / "m.h5", channels={"x": member}, attrs={"x": {}})
    refused(p, words)


def test_samples_stored_outside_the_file_are_refused(tmp_path: Path) -> None:
    p = write(tmp_path / "x.h5")
    (tmp_path / "raw.bin").write_bytes(np.zeros(100).tobytes())
    with h5py.File(p, "a") as f:
        ds = f["channels"].create_dataset(
            "x", shape=(100,), dtype="<f8", external=[(str(tmp_path / "raw.bin"), 0, 800)]
        )
        ds.attrs.update({"units": "V", "sample_rate_hz": FS})
    refused(p, "/channels/x: samples stored in external file(s)", "raw.bin")


# ---------------------------------------------------------------------------- rule 5: floating point
@pytest.mark.parametrize("dtype", ["<i2", "<i4", "<u2", "<c16", "?", "S8"])
def test_channels_are_floating_point_not_counts(tmp_path: Path, dtype: str) -> None:
    x = np.arange(100).astype(dtype)
    msg = refused(
        write(tmp_path / "i.h5", channels={"b": x}),
        f"/channels/b: {np.dtype(dtype)} samples, not floating point",
    )
    if np.dtype(dtype).kind in "iu":
        assert "integer ADC counts are not volts" in msg


# ---------------------------------------------------------------------------- rule 6: units and rate
@pytest.mark.parametrize(
    "units, words",
    [
        (None, "/channels/a: no units attribute"),
        (5, "/channels/a: units = 5 (int64) is not a string"),
        (["V", "mV"], "is not one value"),
        (b"\xff\xfe", "is not UTF-8 text"),
    ],
)
def test_units_are_one_string(tmp_path: Path, units: Any, words: str) -> None:
    refused(write(tmp_path / "u.h5", attrs={"a": {"units": units}}), words)


@pytest.mark.parametrize(
    "rate, words",
    [
        (None, "no sample_rate_hz attribute (a number, Hz)"),
        (math.inf, "sample_rate_hz = inf is not finite"),
        (math.nan, "sample_rate_hz = nan is not finite"),
        (0.0, "sample_rate_hz = 0.0 Hz is not positive"),
        (-5.0, "sample_rate_hz = -5.0 Hz is not positive"),
        (1e-300, "sample_rate_hz = 1e-300 Hz is outside the 0.001 .. 1e+07 Hz this reader accepts"),
        (1e300, "sample_rate_hz = 1e+300 Hz is outside"),
        ("100", "sample_rate_hz = '100' is not a number"),
        (True, "is not a number"),
        (np.array([1.0, 2.0]), "is not one value"),
    ],
)
def test_sample_rate_is_a_number_in_the_documented_range(
    tmp_path: Path, rate: Any, words: str
) -> None:
    refused(
        write(
            tmp_path / "r.h5", attrs={"a": {"sample_rate_hz": rate}, "b": {"sample_rate_hz": rate}}
        ),
        "channels a, b: ",
        words,
    )


def test_the_rate_limits_themselves_are_accepted(tmp_path: Path) -> None:
    for rate in (MIN_RATE_HZ, MAX_RATE_HZ):
        with RunFile(
            write(
                tmp_path / f"r{rate:g}.h5",
                attrs={"a": {"sample_rate_hz": rate}, "b": {"sample_rate_hz": rate}},
            )
        ) as run:
            assert run.rate_hz == rate


def test_channels_share_one_rate(tmp_path: Path) -> None:
    refused(
        write(tmp_path / "r.h5", attrs={"b": {"sample_rate_hz": 200.0}}),
        "channels have different sample rates (100.0 Hz: a; 200.0 Hz: b)",
        "one time base",
    )
    # float32 and float64 of one rate are one rate
    with RunFile(
        write(
            tmp_path / "f.h5",
            attrs={"a": {"sample_rate_hz": np.float32(0.1)}, "b": {"sample_rate_hz": 0.1}},
        )
    ) as run:
        assert run.rate_hz == pytest.approx(0.1, rel=1e-6)


# ---------------------------------------------------------------------------- rule 7: one time base, samples
def test_channels_of_a_closed_file_have_one_length(tmp_path: Path) -> None:
    refused(
        write(tmp_path / "l.h5", channels={"b": np.zeros(90)}),
        "channels have different lengths (90 samples: b; 100 samples: a)",
        "`fbs recover FILE` pads",
    )


def test_a_closed_file_holds_samples(tmp_path: Path) -> None:
    refused(
        write(tmp_path / "z.h5", channels={"a": np.zeros(0), "b": np.zeros(0)}), "holds no samples"
    )


def test_a_live_writers_file_may_be_empty_or_between_channels(tmp_path: Path) -> None:
    """Files being written are exempt from rule 7: a live writer starts with no samples and
    extends its channels one after another (read here in the writer's own process, as the
    console does: HDF5 then shares the writer's open file, not in SWMR mode)."""
    w = RunWriter(tmp_path / "live.h5", rig="t", mode=3, rate_hz=FS, channels={"a": "V", "b": "V"})
    try:
        w.flush()
        with RunFile(w.path) as run:
            assert run.n_samples == 0
        w.append(np.ones((50, 2)))
        w.flush()
        with RunFile(w.path) as run:
            assert run.n_samples == 50
    finally:
        w.close()
    killed = write(
        tmp_path / "killed.h5", channels={"b": np.zeros(90)}, root={"status": "recording"}
    )
    with RunFile(killed) as run:
        assert run.lengths == {"a": 100, "b": 90} and run.n_samples == 90


# ---------------------------------------------------------------------------- rule 8: events, meta
def test_events_are_a_table_of_time_kind_text(tmp_path: Path) -> None:
    refused(write(tmp_path / "e.h5", events=np.arange(3.0)), "/events lacks time, kind or text")
    p = write(tmp_path / "g.h5")
    with h5py.File(p, "a") as f:
        f.create_group("events")
    refused(p, "/events is a Group")
    bad_time = np.array(
        [(b"x", b"mode", b"mode 3")], dtype=[("time", "S4"), ("kind", "S8"), ("text", "S16")]
    )
    refused(write(tmp_path / "t.h5", events=bad_time), "/events time is |S4: it must be a number")


def test_every_rule_broken_is_named_at_once(tmp_path: Path) -> None:
    msg = refused(
        write(
            tmp_path / "m.h5",
            channels={"b": np.zeros(100, dtype="<i2")},
            attrs={"a": {"units": None}, "b": {"sample_rate_hz": math.inf}},
        ),
        "breaks the fbs-run version 1 layout:",
        "/channels/b: int16 samples",
        "/channels/a: no units attribute",
        "/channels/b: sample_rate_hz = inf is not finite",
    )
    assert str(tmp_path / "m.h5") in msg


def test_the_refusal_is_a_run_file_error_and_so_an_os_error() -> None:
    """The command line maps OSError (and ValueError) to ``fbs <cmd>: error:`` and exit 2."""
    assert issubclass(ContractError, RunFileError) and issubclass(UnreadableRunFile, RunFileError)
    assert issubclass(RunFileError, OSError)


# ---------------------------------------------------------------------------- lost samples, described
def test_lost_samples_are_described_by_channel_count_and_span() -> None:
    x = np.zeros(1000)
    x[500:510] = np.nan
    x[900] = np.inf
    assert nonfinite_spans(x) == [(500, 510), (900, 901)]
    assert lost_samples("gyro_x", x, 200.0) == (
        "gyro_x has 10 lost (NaN) and 1 infinite samples: samples 500..509 "
        "(2.500..2.545 s), samples 900..900 (4.500..4.500 s)"
    )
    assert lost_samples("gyro_x", np.zeros(5), 200.0) is None
    assert "samples 1500..1509" in str(lost_samples("a", x[:600], 200.0, offset=1000))


def test_lost_spans_are_found_a_block_at_a_time_across_block_boundaries(tmp_path: Path) -> None:
    x = np.zeros(100)
    x[10:30] = np.nan
    x[63:65] = np.inf
    x[99] = np.nan
    p = write(tmp_path / "l.h5", channels={"a": x})
    with RunFile(p) as run:
        for block in (1, 7, 16, 1000):
            assert run.lost_spans("a", block_samples=block) == [(10, 30), (63, 65), (99, 100)]
        assert run.lost_spans("a", 20, 64, block_samples=8) == [(20, 30), (63, 64)]
        assert run.lost_spans("b") == []
