"""Reading run files: any writer's file, lazy channels, time slices, blocks in bounded memory."""

from __future__ import annotations

import tracemalloc

import h5py
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from daq.reader import RunFile, read_channels
from daq.runfile import RunFileError, RunWriter

FS = 50.0


@pytest.fixture(scope="module")
def run_path(tmp_path_factory):
    p = tmp_path_factory.mktemp("reader") / "r.h5"
    x = np.arange(1000 * 3, dtype=float).reshape(1000, 3)  # sample k of channel j = 3k + j
    with RunWriter(
        p, rig="test", mode=3, rate_hz=FS, channels={"a": "V", "b": "V", "c": "rad"}
    ) as w:
        w.append(x)
        w.event(2.5, "step", "bias 0.1 V")
    return p


def test_description(run_path):
    with RunFile(run_path) as run:
        assert run.channels == ("a", "b", "c") and run.units["c"] == "rad"
        assert (run.rate_hz, run.n_samples, run.duration_s) == (FS, 1000, 20.0)
        assert run.status == "complete" and not run.swmr
        assert [(e.time_s, e.kind, e.text) for e in run.events] == [(2.5, "step", "bias 0.1 V")]
        assert "software_version" in run.meta


def test_channels_are_lazy_arrays(run_path):
    with RunFile(run_path) as run:
        b = run.channel("b")
        assert len(b) == 1000 and b.units == "V"
        np.testing.assert_array_equal(b[10:13], [31.0, 34.0, 37.0])
        assert b[-1] == 3 * 999 + 1 and b[0] == 1.0
        np.testing.assert_array_equal(b[::250], [1.0, 751.0, 1501.0, 2251.0])
        assert np.asarray(b).shape == (1000,)
        with pytest.raises(IndexError, match="sample 1000 outside channel b"):
            b[1000]


def test_time_slices_follow_t_equals_index_over_rate(run_path):
    with RunFile(run_path) as run:
        s = run.slice_s(1.0, 1.1, ["c"])  # t = 1.00, 1.02, ..., 1.08
        assert (s.start, len(s)) == (50, 5)
        np.testing.assert_array_equal(s["c"], 3 * np.arange(50, 55) + 2)
        np.testing.assert_allclose(s.time_s, [1.0, 1.02, 1.04, 1.06, 1.08])
        tail = run.slice_s(19.97, 99.0)  # clipped at the end: t = 19.98 only
        assert (tail.start, tail.stop) == (999, 1000)
        with pytest.raises(ValueError, match="reversed"):
            run.slice_s(2.0, 1.0)


@settings(max_examples=60, deadline=None)
@given(
    size=st.integers(1, 400),
    overlap_frac=st.floats(0, 0.95),
    start=st.integers(0, 999),
    stop=st.integers(0, 1100),
)
def test_blocks_tile_the_range_exactly(run_path, size, overlap_frac, start, stop):
    overlap = min(size - 1, int(size * overlap_frac))
    with RunFile(run_path) as run:
        blocks = list(run.blocks(size, channels=["a"], overlap=overlap, start=start, stop=stop))
    end = min(stop, 1000)
    if start >= end:
        assert blocks == []
        return
    assert blocks[0].start == start and blocks[-1].stop == end
    for prev, nxt in zip(blocks, blocks[1:]):
        assert len(prev) == size and nxt.start == prev.stop - overlap
    for b in blocks:
        np.testing.assert_array_equal(b["a"], 3 * np.arange(b.start, b.stop))


def test_errors_name_the_problem(run_path, tmp_path):
    with RunFile(run_path) as run:
        with pytest.raises(RunFileError, match=r"lacks channel\(s\) zz \(has a, b, c\)"):
            run.read(["zz"])
        with pytest.raises(ValueError, match="outside"):
            run.read(["a"], 10, 2000)
        with pytest.raises(ValueError, match="exactly one"):
            next(run.blocks())
    with h5py.File(tmp_path / "other.h5", "w") as f:
        f.attrs["format"] = "something"
    with pytest.raises(RunFileError, match="not an fbs-run file"):
        RunFile(tmp_path / "other.h5")
    with pytest.raises(RunFileError, match="no such file"):
        RunFile(tmp_path / "missing.h5")
    with h5py.File(tmp_path / "rates.h5", "w") as f:
        f.attrs["format"] = "fbs-run"
        for name, fs in (("a", 10.0), ("b", 20.0)):
            f.create_dataset(f"channels/{name}", data=np.zeros(4)).attrs["sample_rate_hz"] = fs
    with pytest.raises(RunFileError, match="different sample rates"):
        RunFile(tmp_path / "rates.h5")


def test_a_minimal_contract_file_from_another_writer_is_read(tmp_path):
    """DESIGN section 6: analysis accepts any file that follows the contract, whoever wrote it."""
    p = tmp_path / "foreign.h5"
    with h5py.File(p, "w") as f:  # plain h5py, default libver, variable-length strings
        f.attrs.update(
            {
                "format": "fbs-run",
                "format_version": 1,
                "created": "1974-06-01T00:00:00Z",
                "rig": b"FBS",
                "mode": 3,
            }
        )
        for name in ("gyro_x", "ac_x"):
            ds = f.create_dataset(f"channels/{name}", data=np.linspace(0, 1, 11), dtype="f4")
            ds.attrs["units"] = b"V"
            ds.attrs["sample_rate_hz"] = 10
        ev = np.array(
            [(0.5, "mode", "mode 3")],
            dtype=[("time", "f8"), ("kind", h5py.string_dtype()), ("text", h5py.string_dtype())],
        )
        f.create_dataset("events", data=ev)
    with RunFile(p) as run:
        assert run.attrs["rig"] == "FBS" and run.units["ac_x"] == "V" and run.rate_hz == 10.0
        assert run.status == "" and run.events[0].text == "mode 3"
        np.testing.assert_allclose(run.read(["ac_x"])[0], np.linspace(0, 1, 11), rtol=1e-7)
    data, fs = read_channels(p, ["gyro_x"])
    assert fs == 10.0 and data["gyro_x"].shape == (11,)


def test_block_iteration_memory_is_one_block_not_the_file(tmp_path):
    """Files larger than RAM: the reader's peak allocation is set by the block, not the file.

    64 MB on disk (16 channels x 500k samples); blocks of 20k samples (2.5 MB) must stay
    under 3 blocks' worth of Python-side memory."""
    p = tmp_path / "big.h5"
    n, c = 500_000, 16
    chunk = np.random.default_rng(0).standard_normal((50_000, c))
    with RunWriter(
        p, rig="test", mode=3, rate_hz=1e4, channels={f"ch{i}": "V" for i in range(c)}
    ) as w:
        for _ in range(n // len(chunk)):
            w.append(chunk)
    total = 0.0
    tracemalloc.start()
    try:
        with RunFile(p) as run:
            for b in run.blocks(20_000):
                total += float(b.data.sum())
            _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    block_bytes, file_bytes = 20_000 * c * 8, n * c * 8
    assert peak < 3 * block_bytes and peak < file_bytes / 8, f"peak {peak / 1e6:.1f} MB"
    assert total == pytest.approx(chunk.sum() * (n // len(chunk)), rel=1e-9)
