"""Every fault of issue 3 point 5, provoked through the emulated devices (acceptance B).

Each test checks the typed error, its message, the exact sample positions where data were
lost, and the state of the rig afterwards: device faults latch and drive the rig safe (read
back from the emulated nodes themselves); lost samples are reported and the stream goes on.
"""

from __future__ import annotations

import time

import pytest

from drivers import can_protocol as cp
from drivers.errors import DeviceLost, DeviceTimeout, NodeError, NodeReset, ProtocolError, SampleGap
from drivers.rig import open_rig

pytestmark = pytest.mark.slow

FRAME = 10  # sample sets per frame in these tests


@pytest.fixture
def rig():
    r = open_rig("sim?warm=1&watchdog=1")   # the watchdog tests: the real rig's 1 s
    r.set_torquer_bias_V("X", 1.5)
    r.set_command_torque_V("Y", 0.5)
    r.set_caging_inhibit("Z", True)
    yield r
    r.close()


def stream(rig, rate=1000.0):
    rig.adc.configure(["gyro_x", "torq_x", "ac_x_ctl"], rate, frame_sets=FRAME)
    rig.adc.start()
    first = rig.adc.read(200)
    assert first.first_sample == 0
    return first.stop_sample


def emulated_nodes_safe(rig, timeout_s=5.0) -> bool:
    """The nodes' own registers (not the host's view): mode 1, outputs zero, caging released."""
    nodes = rig.emulator.nodes.nodes
    t_end = time.monotonic() + timeout_s
    while time.monotonic() < t_end:
        ok = (nodes["relay"].mode == 1 and not any(nodes["torquer"].values.values())
              and not any(nodes["command"].values.values()) and not any(nodes["caging"].inhibit.values()))
        if ok:
            return True
        time.sleep(0.05)
    return False


def read_until_gap(rig, pos):
    """Read on until a SampleGap; every block before it must continue exactly where the last ended."""
    for _ in range(200):
        try:
            b = rig.adc.read(100)
        except SampleGap as gap:
            return pos, gap
        assert b.first_sample == pos
        pos = b.stop_sample
    raise AssertionError("no gap reported")


@pytest.mark.parametrize("fault, reason", [("drop", "missing (sequence counter)"),
                                           ("corrupt", "bad CRC"),
                                           ("bad_length", "bad length")])
def test_lost_frame_is_a_gap_at_exact_positions(rig, fault, reason):
    pos = stream(rig)
    rig.emulator.inject("adc", fault)
    pos, gap = read_until_gap(rig, pos)
    assert reason in gap.reason and reason in str(gap)
    assert gap.start == pos and gap.start % FRAME == 0 and gap.stop - gap.start == FRAME
    assert f"ADC samples {gap.start}..{gap.stop - 1} lost ({FRAME} sample sets)" in str(gap)
    after = rig.adc.read(100)
    assert after.first_sample == gap.stop  # the stream goes on after the gap, never spliced over it
    # Samples lost are not a hazard: the rig keeps its mode and set-points, no fault is latched.
    assert rig.faults.fault is None
    assert rig.relays.status().mode == 3 and rig.torquers.bias_V("X") == pytest.approx(1.5, abs=1e-3)
    status = rig.adc.stop()
    assert status.samples > gap.stop


def test_two_dropped_frames_name_both_sequence_numbers(rig):
    pos = stream(rig)
    rig.emulator.inject("adc", "drop", count=2)
    pos, gap = read_until_gap(rig, pos)
    assert gap.stop - gap.start == 2 * FRAME and gap.start == pos
    seq = gap.start // FRAME
    assert f"seq {seq}..{seq + 1} missing" in gap.reason


def test_garbage_between_frames_costs_no_samples(rig):
    pos = stream(rig)
    rig.emulator.inject("adc", "garbage", nbytes=300)
    for _ in range(10):
        b = rig.adc.read(100)
        assert b.first_sample == pos
        pos = b.stop_sample
    assert rig.faults.fault is None


def test_unknown_reply_is_a_protocol_error_and_the_rig_goes_safe(rig):
    rig.emulator.inject("adc", "bad_reply")
    with pytest.raises(ProtocolError, match=r"unexpected reply 'OK HELLO from a confused device' to 'STAT\?'"):
        rig.adc.status()
    assert emulated_nodes_safe(rig)
    assert rig.is_safe()
    with pytest.raises(ProtocolError):  # latched: every later call says what went wrong
        rig.set_torquer_bias_V("X", 0.1)


def test_adc_stall_is_a_device_timeout_and_the_rig_goes_safe(rig):
    stream(rig)
    rig.adc.stall_timeout_s = 0.5
    rig.emulator.inject("adc", "stall")
    with pytest.raises(DeviceTimeout, match=r"stalled: no data for 0\.5 s while streaming at 1000 Hz"):
        for _ in range(1000):
            rig.adc.read(100)
    assert emulated_nodes_safe(rig)
    assert isinstance(rig.faults.fault, DeviceTimeout)


def test_pulled_adc_cable_is_device_lost_and_the_rig_goes_safe(rig):
    stream(rig)
    rig.emulator.inject("adc", "disconnect")
    with pytest.raises(DeviceLost, match="serial device went away"):
        for _ in range(1000):
            rig.adc.read(100)
    assert emulated_nodes_safe(rig)
    with pytest.raises(DeviceLost):
        rig.set_mode(2)


def test_adc_no_reply_is_a_device_timeout(rig):
    rig.adc.reply_timeout_s = 0.3
    rig.emulator.inject("adc", "stall", seconds=1.0)
    with pytest.raises(DeviceTimeout, match=r"no reply to 'STAT\?' within 0\.3 s"):
        rig.adc.status()
    assert emulated_nodes_safe(rig)


def test_stalled_node_times_out_and_its_watchdog_makes_it_safe(rig):
    """The host cannot reach the stalled node, so it stops its heartbeat: every watchdog trips."""
    rig.emulator.inject("torquer", "stall")
    with pytest.raises(DeviceTimeout, match=r"CAN node 'torquer' \(id 3\) did not answer SET index 0"):
        rig.set_torquer_bias_V("X", 0.2)
    assert emulated_nodes_safe(rig, timeout_s=5.0)
    assert rig.emulator.nodes.nodes["torquer"].latched  # safe by its own watchdog
    assert rig.link.heartbeat_suspended


def test_silent_node_is_device_lost_and_goes_safe_by_itself(rig):
    rig.emulator.inject("relay", "disconnect")
    t0 = time.monotonic()
    while rig.faults.fault is None and time.monotonic() - t0 < 5.0:
        time.sleep(0.05)
    fault = rig.faults.fault
    assert isinstance(fault, DeviceLost)
    assert "CAN node 'relay' (id 1) is silent: no heartbeat for" in str(fault)
    assert emulated_nodes_safe(rig, timeout_s=5.0)
    assert rig.emulator.sim.mode == 1 or (time.sleep(0.2) or rig.emulator.sim.mode == 1)


def test_node_reset_is_reported_and_the_rig_goes_safe(rig):
    rig.emulator.inject("command", "reset")
    t0 = time.monotonic()
    while rig.faults.fault is None and time.monotonic() - t0 < 3.0:
        time.sleep(0.02)
    assert isinstance(rig.faults.fault, NodeReset)
    assert "CAN node 'command' (id 4) rebooted and lost its set-points" in str(rig.faults.fault)
    assert emulated_nodes_safe(rig)
    with pytest.raises(NodeReset):
        rig.set_ac_bias_V("X", 0.1)


def test_node_error_frame_is_reported_with_its_code(rig):
    rig.emulator.inject("torquer", "error", code=cp.EMCY_OVERTEMP)
    t0 = time.monotonic()
    while rig.faults.fault is None and time.monotonic() - t0 < 3.0:
        time.sleep(0.02)
    fault = rig.faults.fault
    assert isinstance(fault, NodeError) and fault.code == 0x4210 and fault.node == "torquer"
    assert "over-temperature (code 0x4210" in str(fault)
    assert emulated_nodes_safe(rig)


def test_malformed_response_is_a_protocol_error(rig):
    rig.emulator.inject("caging", "bad_response")
    with pytest.raises(DeviceTimeout):
        rig.set_caging_inhibit("X", True)  # the answer never arrives in a usable form
    assert isinstance(rig.faults.fault, ProtocolError)
    assert "bad length 5 (expected 8)" in str(rig.faults.fault)
    assert emulated_nodes_safe(rig)


def test_host_heartbeat_loss_trips_every_watchdog():
    """The host dies (no heartbeat): each node goes safe by itself and says so."""
    rig = open_rig("sim?warm=1&watchdog=1")
    try:
        rig.set_torquer_bias_V("Y", -1.0)
        rig.link.heartbeat_suspended = True
        assert emulated_nodes_safe(rig, timeout_s=5.0)
        nodes = rig.emulator.nodes.nodes
        # the rig is safe once the first watchdog trips; each node's own trips within its period
        t0 = time.monotonic()
        while not all(nodes[n].latched for n in ("relay", "caging", "torquer", "command")) \
                and time.monotonic() - t0 < 5.0:
            time.sleep(0.02)
        assert all(nodes[n].latched for n in ("relay", "caging", "torquer", "command"))
        t0 = time.monotonic()
        while rig.faults.fault is None and time.monotonic() - t0 < 3.0:
            time.sleep(0.02)
        assert isinstance(rig.faults.fault, (NodeError, DeviceLost))
    finally:
        rig.close()


def test_gap_positions_match_the_data_the_device_sent(rig):
    """Cross-check with the device's own count: samples received plus samples reported lost is
    exactly what it sent, and the gaps sit where the received blocks leave holes."""
    pos = stream(rig)
    received, lost = pos, 0
    for fault in ("drop", "corrupt"):
        rig.emulator.inject("adc", fault)
        before = pos
        pos, gap = read_until_gap(rig, pos)
        received += pos - before
        lost += gap.stop - gap.start
        pos = gap.stop
    status = rig.adc.stop()
    while True:
        b = rig.adc.read_available()
        if b is None:
            break
        assert b.first_sample == pos
        received += len(b)
        pos = b.stop_sample
    assert lost == 2 * FRAME
    assert received + lost == status.samples == pos


def test_a_busy_host_does_not_fail_the_simulated_rig():
    """Issue 19 item 10: answers 1.5 s late (a host too loaded to schedule the node's thread;
    a full `make test` once failed at the 0.5 s reply deadline). The sim rig's time is virtual,
    so its wall-clock deadlines default to 5 s; with the real rig's 1 s the same delay is the
    timeout it should be."""
    rig = open_rig("sim?warm=1")
    try:
        rig.emulator.inject("torquer", "busy", delay_s=1.5)
        assert rig.set_torquer_bias_V("X", 0.2) == pytest.approx(0.2, abs=1e-3)
        assert rig.faults.fault is None
    finally:
        rig.close()
    rig = open_rig("sim?warm=1&watchdog=1")
    try:
        rig.emulator.inject("torquer", "busy", delay_s=1.5)
        with pytest.raises(DeviceTimeout, match="did not answer"):
            rig.set_torquer_bias_V("X", 0.2)
    finally:
        rig.close()
