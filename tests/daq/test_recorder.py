"""The recorder on the loopback rig: gaps stay gaps, faults close the file with their reason."""

from __future__ import annotations

import threading

import h5py
import numpy as np
import pytest

from daq.recorder import record
from drivers.errors import DeviceLost
from drivers.rig import open_rig

pytestmark = pytest.mark.slow


def test_a_dropped_frame_is_nan_with_a_gap_event(tmp_path):
    with open_rig("sim?warm=1") as rig:
        rig.emulator.inject("adc", "drop")  # the stream's first frame (samples 0..9 at 1 kHz)
        result = record(
            rig, tmp_path / "r.h5", duration_s=1.0, rate_hz=1000.0, channels=["gyro_x", "ac_x_ctl"]
        )
    assert result.gaps == [(0, 10, result.gaps[0][2])] and "missing" in result.gaps[0][2]
    with h5py.File(tmp_path / "r.h5", "r") as f:
        x = f["channels/gyro_x"][()]
        assert len(x) == 1000 and np.isnan(x[:10]).all() and np.isfinite(x[10:]).all()
        kinds = [k.decode() for k in f["events"]["kind"]]
        assert "gap" in kinds
        gap = f["events"][kinds.index("gap")]
        assert gap["time"] == 0.0 and b"ADC samples 0..9 lost" in gap["text"]
        assert f.attrs["status"] == "complete"


def test_a_lost_node_aborts_the_recording_and_the_rig_goes_safe(tmp_path):
    # the real rig's 1 s node timeout: with the sim's 5 s default the virtual-time recording
    # can finish before the loss is noticed
    rig = open_rig("sim?warm=1&watchdog=1")
    try:
        pull = threading.Timer(0.5, rig.emulator.inject, ("relay", "disconnect"))
        pull.start()  # the relay node's cable comes out while the recording runs
        with pytest.raises(DeviceLost, match="relay"):
            record(rig, tmp_path / "r.h5", duration_s=600.0, rate_hz=1000.0, channels=["gyro_x"])
        with h5py.File(tmp_path / "r.h5", "r") as f:
            assert f.attrs["status"].startswith(
                "aborted: DeviceLost: CAN node 'relay' (id 1) is silent"
            )
            kinds = [k.decode() for k in f["events"]["kind"]]
            assert "error" in kinds
            assert len(f["channels/gyro_x"]) > 0
        nodes = rig.emulator.nodes.nodes
        assert not any(nodes["torquer"].values.values()) and not any(
            nodes["command"].values.values()
        )
    finally:
        rig.close()


def test_record_goes_safe_through_the_drivers_one_guard_before_the_file_closes(
    tmp_path, go_safe_calls
):
    """``record`` (``fbs record``) drives the rig safe through ``drivers.safety``; the safe state
    is in the file, which is closed "aborted"; the recorder itself commands nothing."""
    with open_rig("sim?warm=1") as rig:
        rig.set_torquer_bias_V("X", 0.3)
        stop = threading.Timer(0.3, rig.emulator.inject, ("adc", "disconnect"))
        stop.start()
        with pytest.raises(DeviceLost):
            record(rig, tmp_path / "r.h5", duration_s=600.0, rate_hz=1000.0, channels=["gyro_x"])
        assert go_safe_calls and go_safe_calls[0].startswith("recording aborted (DeviceLost")
        assert len(go_safe_calls) == 1
        assert rig.is_safe() and not any(rig.emulator.nodes.nodes["torquer"].values.values())
    with h5py.File(tmp_path / "r.h5", "r") as f:
        assert f.attrs["status"].startswith("aborted: DeviceLost")
        kinds = [k.decode() for k in f["events"]["kind"]]
        assert "safe" in kinds


def test_an_acquisition_hands_back_what_it_writes_and_places_commands_on_the_file_time_base(
    tmp_path,
):
    from daq.reader import RunFile
    from daq.recorder import Acquisition

    with open_rig("sim?warm=1") as rig:
        with Acquisition(
            rig, tmp_path / "a.h5", rate_hz=1000.0, channels=["gyro_x", "torq_x"], procedure="unit"
        ) as acq:
            first = acq.acquire(0.5)
            rig.set_torquer_bias_V("X", 0.2)  # lands between blocks, at file time 0.5 s
            acq.note("step", "bias step")
            rig.emulator.inject("adc", "drop")  # a frame the device sends next (10 samples) is lost
            second = acq.acquire(0.5)
        assert acq.result.status == "complete" and acq.result.samples == 1000
        ((a, b, _),) = acq.result.gaps
    with RunFile(tmp_path / "a.h5") as run:
        on_disk = run.read(["gyro_x", "torq_x"]).T
        events = {e.kind: e for e in run.events}
        assert run.attrs["procedure"] == "unit"
    np.testing.assert_array_equal(np.vstack([first, second]), on_disk)
    lost = np.isnan(second).all(axis=1)
    assert (
        b - a == 10
        and lost[a - 500 : b - 500].all()
        and lost.sum() == 10
        and np.isfinite(first).all()
    )
    # the command's rig time: after the samples read so far, before the device's next block
    assert 0.5 <= events["setpoint"].time_s <= 0.6 and events["step"].time_s == 0.5
