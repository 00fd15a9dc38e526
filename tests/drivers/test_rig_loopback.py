"""End-to-end on the loopback rig: the real drivers talk bytes over a pty and a virtual CAN bus
to the simulated devices (issue 3, acceptance A)."""

from __future__ import annotations

import can
import numpy as np
import pytest

from drivers.errors import (
    InterlockError,
    ModeNotAllowed,
    OperatorAbort,
    SampleGap,
    SetpointRangeError,
)
from drivers.relay import R_SELECTED, R_SWITCHES, SWITCH_HOLD, SWITCH_RELEASE
from drivers.rig import STREAM_READ_S, open_rig
from drivers.table import ManualTable
from tests.drivers.waiting import wait_for

pytestmark = pytest.mark.slow

SENSE = -10.00e-3 * 92.1  # torquer volts per bias volt: K_TB x sense resistor (II C.1.a(1))


def drain(bus: can.BusABC) -> list[int]:
    """Identifiers of every frame the spy saw (the bus never goes quiet: heartbeats)."""
    ids = []
    while (m := bus.recv(0.0)) is not None:
        ids.append(m.arbitration_id)
    return ids


#: CANopen function codes of what a host sends: NMT, receive PDOs 1-4, SDO requests
HOST_FUNCTIONS = (0x000, 0x200, 0x300, 0x400, 0x500, 0x600)


def commands(frames: list[int]) -> list[int]:
    """The frames of ``frames`` that command a node (the host heartbeat only keeps them alive)."""
    return [i for i in frames if i & 0x780 in HOST_FUNCTIONS]


@pytest.fixture
def rig():
    r = open_rig("sim")
    yield r
    r.close()


def test_adc_configure_stream_and_stop(rig):
    """16 channels with their own ranges stream without loss; the device counts what it sent."""
    ident = rig.adc.identity
    assert ident.model == "SIM-ADC16" and len(ident.channels) == 19
    chans = ident.channels[:16]
    ranges = dict.fromkeys(chans, 10.0)
    ranges["ac_x_ctl"] = 0.1
    cfg = rig.adc.configure(chans, 2000.0, ranges)
    assert cfg.channels == chans and cfg.ranges_V["ac_x_ctl"] == 0.1 and cfg.frame_sets == 20
    t0 = rig.adc.start()
    got, pos = [], 0
    while pos < 6000:
        b = rig.adc.read(1500)
        assert b.first_sample == pos and b.channels == chans
        assert (
            b.volts.shape == (len(b), 16) and b.volts.T.flags.c_contiguous
        )  # channel-major in memory
        got.append(b.volts)
        pos = b.stop_sample
    status = rig.adc.stop()
    assert status.samples >= 6000 and status.overruns == 0
    tail = []
    while (b := rig.adc.read_available()) is not None:
        assert b.first_sample == pos
        tail.append(b.volts)
        pos = b.stop_sample
    assert pos == status.samples  # every sample the device sent arrived, none twice
    v = np.concatenate(got)
    lsb = np.array([ranges[c] / 32768.0 for c in chans])
    codes = np.rint(v / lsb)
    assert (
        np.array_equal(codes * lsb, v) and codes.min() >= -32768 and codes.max() <= 32767
    )  # each its own range
    # The autocollimator noise (NEA ~0.45 urad x 5.7 mV/urad) is resolved on the 0.1 V range.
    ac = v[:, chans.index("ac_x_ctl")]
    assert 1e-3 < np.std(ac) < 1e-2
    assert np.ptp(ac) / (0.2 / 65536) > 20  # many codes, not one
    assert rig.now() - t0 >= 3.0 - 1e-9  # whole samples of sim time; allow an ulp


def test_every_dac_reads_back_and_acts(rig):
    """Each torquer bias, command output and caging switch is set, read back, and seen by the physics."""
    rig.adc.configure(["torq_x", "torq_y", "torq_z", "torq_xrd", "cmd_x", "cmd_y", "cmd_z"], 1000.0)
    biases = {"X": 1.0, "Y": -2.5, "Z": 0.5, "XRD": 3.25}
    for ch, v in biases.items():
        back = rig.set_torquer_bias_V(ch, v)
        assert abs(back - v) <= 20.0 / 65536
        assert rig.torquers.bias_V(ch) == back
    for i, a in enumerate("XYZ"):
        assert abs(rig.set_command_torque_V(a, 0.1 * (i + 1)) - 0.1 * (i + 1)) <= 20.0 / 65536
        assert abs(rig.set_ac_bias_V(a, -0.05) + 0.05) <= 20.0 / 65536
        assert abs(rig.commands.command_torque_V(a) - 0.1 * (i + 1)) <= 20.0 / 65536
    for ch in ("X", "Z"):
        assert rig.set_caging_inhibit(ch, True) is True
        assert rig.caging.inhibited(ch) is True
    assert rig.caging.inhibited("Y") is False
    rig.adc.start()
    rig.wait(0.5)  # settings land at the next block; let filters settle
    b = rig.adc.read(1000)
    rig.adc.stop()
    tail = b.volts[-200:].mean(axis=0)
    for i, (ch, v) in enumerate(biases.items()):
        assert tail[i] == pytest.approx(SENSE * v, abs=2e-3), (
            ch
        )  # mode 1: the bias drives the torquer
    for i in range(3):
        assert tail[4 + i] == pytest.approx(0.1 * (i + 1) - 0.05, abs=2e-3)  # cmd = V_Td + gamma_c
    sim = rig.emulator.sim
    assert sim.relays.caging_inhibit == (True, False, True, False)


#: set-points of 4 ms in the stream test: two whole reads of the stream and part of a third
STREAM_N = int(round(2.5 * STREAM_READ_S / 0.004))


def _streamed(scheduled: bool) -> np.ndarray:
    """cmd_x and pa_x while V_Td steps every 4 ms on a fresh rig in Mode 3: the rig's own
    stream (scheduled by the rig, read ``STREAM_READ_S`` at a time: two whole reads and a part)
    or each set-point followed by its read."""
    values = 0.2 * np.sin(0.7 * np.arange(STREAM_N))
    with open_rig("sim?seed=3") as r:
        r.set_mode(3)
        r.wait(2.0)
        r.adc.configure(["cmd_x", "pa_x"], 1000.0)
        r.adc.start()
        got = [r.adc.read(30).volts]
        if scheduled:
            r.stream_command_torque_V(
                "X", values, 0.004, lambda s: got.append(r.adc.read(round(s * 1e3)).volts)
            )
        else:
            for v in values:
                r.commands.put_command_torque_V("X", float(v))
                got.append(r.adc.read(4).volts)
            r.set_command_torque_V("X", 0.0)
        got.append(r.adc.read(30).volts)
        r.adc.stop()
        return np.concatenate(got)


def test_a_stream_scheduled_by_the_rig_lands_where_reads_between_set_points_land_it():
    """``Rig.stream_command_torque_V`` paces its set-points by the rig's clock and reads
    ``STREAM_READ_S`` at a time (the sim rig simulates each read as one block, the set-points
    stepping inside it): every set-point lands at the sample it lands at when a 4 ms read
    follows each, to the bit."""
    scheduled, paced_by_reads = _streamed(True), _streamed(False)
    assert scheduled.shape == paced_by_reads.shape == (30 + 4 * STREAM_N + 30, 2)
    assert np.ptp(scheduled[:, 0]) > 0.3  # the stream is in the record
    assert np.array_equal(scheduled, paced_by_reads)


def test_modes_1_2_3_4_with_spin_up_and_caging(rig):
    """Hold/select/release through 1-2-3, then 4 once the wheels are at speed and the gyros caged."""
    st = rig.relays.status()
    assert st.mode == 1 and not any(st.at_speed.values())
    with pytest.raises(InterlockError, match="not at speed"):
        rig.set_mode(4)
    assert rig.relays.status().mode == 1
    assert rig.set_mode(2) == 2
    t_ready = rig.wait_until(
        lambda: all(rig.relays.status().at_speed.values()),
        timeout_s=300,
        poll_s=2.0,
        what="wheels at speed",
    )
    assert 100.0 < t_ready < 200.0  # 99 % in the configured 120 s, polled every 2 s
    assert rig.set_mode(3) == 3
    with pytest.raises(InterlockError, match="not caged"):
        rig.set_mode(4)  # the caging loops have only just closed
    rig.wait_until(
        lambda: all(rig.relays.status().caged.values()), timeout_s=600, poll_s=2.0, what="caged"
    )
    assert rig.set_mode(4) == 4
    st = rig.relays.status()
    assert st.mode == 4 and not st.held and not st.alarm
    assert rig.emulator.sim.mode == 4 or (rig.wait(0.1) or rig.emulator.sim.mode == 4)
    rig.adc.configure(["gyro_x", "torq_x", "ac_x_ctl"], 500.0)
    rig.adc.start()
    b = rig.adc.read(500)
    rig.adc.stop()
    assert np.all(np.isfinite(b.volts)) and not b.overrange.any()


def test_disallowed_mode_lights_alarm_and_sends_nothing(rig):
    spy = can.Bus(interface="virtual", channel=rig.emulator.can_channel)
    try:
        for bad in (0, 7, 8, -1, 2.0, "3"):
            with pytest.raises(ModeNotAllowed, match=f"mode {bad!r}|mode {bad}"):
                rig.set_mode(bad)
            assert rig.relays.alarm and "not allowed" in rig.relays.alarm
        seen = drain(spy)
    finally:
        spy.shutdown()
    assert not commands(seen)  # no request left the host
    assert rig.relays.status().mode == 1
    rig.set_mode(2)
    assert rig.relays.alarm is None


def test_relay_node_refuses_mode_7_itself(rig):
    """Defence in depth: a host that skips the check still cannot clock mode 7 in."""
    node = rig.relays.node
    node.write(R_SWITCHES, 0, SWITCH_HOLD)
    with pytest.raises(SetpointRangeError, match="SELECT mode 7"):
        node.write(R_SELECTED, 0, 7, what="SELECT mode 7")
    assert rig.relays.status().alarm
    node.write(R_SWITCHES, 0, SWITCH_RELEASE)
    assert rig.relays.status().mode == 1


def test_setpoints_out_of_range_never_reach_the_bus(rig):
    spy = can.Bus(interface="virtual", channel=rig.emulator.can_channel)
    try:
        cases = [
            (
                lambda: rig.set_torquer_bias_V("X", 8.1),
                r"8\.1 is outside \+-8\.0767.*3\.5 x earth-rate",
            ),
            (lambda: rig.set_torquer_bias_V("Y", -7.7), r"-7\.7 is outside \+-7\.64"),
            (lambda: rig.set_torquer_bias_V("W", 1.0), r"gyro channel 'W' does not exist"),
            (lambda: rig.set_torquer_bias_V("X", float("nan")), r"nan is outside"),
            (
                lambda: rig.set_command_torque_V("X", 10.5),
                r"10\.5 is outside \+-10 \(the DAC's range\)",
            ),
            (lambda: rig.set_ac_bias_V("Q", 1.0), r"axis 'Q' does not exist"),
            (lambda: rig.set_caging_inhibit("X", 1), r"must be True or False"),
            (lambda: rig.move_table(tilt_deg=91.0), r"91\.0 is outside 0\.\.90"),
            (lambda: rig.adc.configure(["gyro_x", "nope"], 1000), r"channel 'nope' does not exist"),
            (lambda: rig.adc.configure(["gyro_x"], 3e6), r"outside 0 < rate <= 2e\+06"),
            (
                lambda: rig.adc.configure(["gyro_x"], 1000, 3.0),
                r"range 3\.0 V for gyro_x is not available",
            ),
        ]
        for call, message in cases:
            with pytest.raises(SetpointRangeError, match=message):
                call()
        frames = drain(spy)
    finally:
        spy.shutdown()
    assert not commands(frames)
    assert rig.faults.fault is None  # a refusal is not a fault: the rig did not move


def test_motorized_table_moves(rig):
    pos = rig.move_table(tilt_deg=0.0, spindle_deg=390.0)
    assert pos.spindle_deg == pytest.approx(30.0) and pos.tilt_deg == 0.0
    rig.wait(0.05)
    assert rig.emulator.sim.cfg.table.spindle_deg == pytest.approx(30.0)


def test_manual_table_asks_the_operator():
    asked = []

    def operator(prompt: str) -> str:
        asked.append(prompt)
        return "" if len(asked) == 1 else ("30.01" if len(asked) == 2 else "abort")

    table = ManualTable(operator)
    assert table.move_to(spindle_deg=60.0).spindle_deg == 60.0
    assert "spindle 60.0000 deg" in asked[0]
    assert table.move_to(spindle_deg=30.0).spindle_deg == pytest.approx(
        30.01
    )  # the angle actually set
    with pytest.raises(OperatorAbort):
        table.move_to(spindle_deg=90.0)
    assert table.position().spindle_deg == pytest.approx(30.01)
    assert table.move_to(spindle_deg=30.01).spindle_deg == pytest.approx(
        30.01
    )  # no move, no question
    assert len(asked) == 3


def test_close_leaves_the_rig_safe():
    rig = open_rig("sim?warm=1")
    assert rig.relays.status().mode == 3
    rig.set_torquer_bias_V("X", 2.0)
    rig.set_command_torque_V("Y", 1.0)
    server = rig.emulator
    report = rig.close()
    assert report.ok, report.failed
    nodes = server.nodes.nodes
    assert nodes["relay"].mode == 1
    assert all(v == 0 for v in nodes["torquer"].values.values())
    assert all(v == 0 for v in nodes["command"].values.values())


def test_bad_rig_url_is_named():
    with pytest.raises(ValueError, match="unknown parameter.*bogus"):
        open_rig("sim?bogus=1")
    with pytest.raises(ValueError, match="unknown rig"):
        open_rig("tcp://x")
    with pytest.raises(ValueError, match="can=<interface>:<channel>"):
        open_rig("serial:///dev/ttyUSB9")


def test_a_full_host_buffer_keeps_whole_frames_and_reports_the_rest_lost():
    """Paced, nobody reading: the host keeps the frames that fit its buffer, whole (the reader
    takes a run of them as one item), reports the rest as a host overrun, and goes on after it."""
    rig = open_rig("sim?realtime=1&warm=1")
    try:
        # the serial driver's setting, through the rig's decorator (``AdcDecorator.__setattr__``):
        # 45 sets at 1000 Hz, 22 frames of 2 fit, the 23rd does not
        rig.adc.buffer_s = 0.045
        rig.adc.configure(["gyro_x", "ac_x_ctl"], 1000.0, frame_sets=2)
        rig.adc.start()
        wait_for(lambda: rig.adc.status().samples > 200, "the device 0.2 s into its stream")
        kept = rig.adc.read(45)
        assert (kept.first_sample, len(kept)) == (0, 44)
        with pytest.raises(SampleGap, match="host buffer overrun") as lost:
            rig.adc.read(10)
        assert lost.value.start == 44 and lost.value.stop % 2 == 0
        after = rig.adc.read(10)
        assert after.first_sample == lost.value.stop
        rig.adc.stop()
    finally:
        rig.close()


def test_paced_rig_runs_by_itself():
    """``sim?realtime=1``: the rig's clock runs with the wall clock, not on demand."""
    rig = open_rig("sim?realtime=1&warm=1")
    try:
        assert rig.clock.virtual is False
        rig.adc.configure(["gyro_x", "ac_x_ctl"], 1000.0)
        t0 = rig.adc.start()
        b = rig.adc.read(200)
        assert b.first_sample == 0 and len(b) == 200
        # the sim's time is whole samples, so 0.23 + 0.2 may exceed its exact 0.43 by one ulp
        assert rig.now() - t0 >= 0.2 - 1e-9
        rig.adc.stop()
    finally:
        rig.close()


def test_terminal_operator_without_a_terminal_says_so(monkeypatch):
    import io

    monkeypatch.setattr("sys.stdin", io.StringIO(""))
    table = ManualTable()
    with pytest.raises(OperatorAbort, match="needs an operator, but there is no terminal"):
        table.move_to(spindle_deg=30.0)
