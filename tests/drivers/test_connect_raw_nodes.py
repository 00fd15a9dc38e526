"""Issue 35 items 1-4, 7, 12 and B: the host connects to modules as a CiA 301 master would, and
never to a rig another host holds. The modules are ``rawnode.RawNode`` (raw frames, written from
the standards), so nothing here shares code with the sim's nodes or the canopen package's
LocalNode.
"""

from __future__ import annotations

import os
import struct
import subprocess
import sys
import time
import uuid
from contextlib import contextmanager

import can
import pytest

from drivers.can_link import CanLink
from drivers.claim import RigClaim
from drivers.errors import DeviceLost, DeviceTimeout, NodeError, ProtocolError, RigBusy
from drivers.torquer import CanopenTorquerDac
from tests.drivers.rawnode import AO_401_OBJECTS, OPERATIONAL, STOPPED, RawNode
from tests.drivers.waiting import wait_for

TORQUER = 3
EMCY_TRIP = 0x8130


@pytest.fixture
def channel():
    return f"raw-{uuid.uuid4().hex[:8]}"


def host(channel: str, **kw) -> tuple[CanLink, CanopenTorquerDac]:
    bus = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
    link = CanLink(bus, ["torquer"], channel=channel, **kw)
    return link, CanopenTorquerDac(link)


@contextmanager
def module_and_host(
    channel: str, objects: dict = AO_401_OBJECTS, node_kw: dict | None = None, **host_kw
):
    """A raw module on ``channel`` and a host link with the torquer client; both closed after."""
    node = RawNode(channel, TORQUER, objects, **(node_kw or {}))
    try:
        link, dac = host(channel, **host_kw)
    except BaseException:
        node.close()
        raise
    try:
        yield node, link, dac
    finally:
        link.close()
        node.close()


def connect(link: CanLink, dac: CanopenTorquerDac, window_s: float = 2.0) -> int:
    product = dac.node.connect(link.monotonic() + window_s, window_s)
    link.wait_operational(["torquer"], 2.0)
    return product


@pytest.mark.parametrize(
    "case, node_kw",
    [
        ("heartbeat off at power-on (0x1017 = 0)", {}),
        ("boots 1.1 s after the host", {"boot_delay_s": 1.1}),
        ("left stopped by its last master", {"state": STOPPED}),
        ("slow SDO answers (0.2 s)", {"sdo_delay_s": 0.2}),
    ],
)
def test_a_conforming_module_opens(channel, case, node_kw):
    with module_and_host(channel, node_kw=node_kw) as (node, link, dac):
        assert connect(link, dac) == 0x13, case
        # configured as the host asked, read back: its heartbeat now runs, its errors go pre-op
        assert node.objects[(0x1017, 0)][0] == 100 and node.objects[(0x1029, 1)][0] == 0
        assert node.objects[(0x1016, 1)][0] == 0x007F03E8 and node.state == OPERATIONAL
        time.sleep(0.3)
        assert link.faults.fault is None, link.faults.fault


def test_a_module_that_never_answers_is_named_with_the_window(channel):
    with module_and_host(channel, node_kw={"boot_delay_s": 3600}) as (node, link, dac):
        with pytest.raises(
            DeviceLost,
            match=r"'torquer' \(id 3\) did not answer within the connect window of 0.5 s",
        ):
            dac.node.connect(link.monotonic() + 0.5, 0.5)


def test_a_stale_trip_emcy_during_connect_does_not_fail_the_open(channel):
    """Item 7: the previous session's watchdog trip, arriving while this host connects."""
    with module_and_host(channel) as (node, link, dac):
        node.emcy(EMCY_TRIP)
        connect(link, dac)
        assert link.faults.fault is None
        node.emcy(EMCY_TRIP)  # after the start: this session's fault
        wait_for(lambda: link.faults.fault is not None, "the EMCY latched")
        assert isinstance(link.faults.fault, NodeError), link.faults.fault


def test_an_emcy_that_is_not_8_bytes_latches(channel):
    """Item 4: it raised inside the canopen package's EMCY handler and latched nothing."""
    with module_and_host(channel) as (node, link, dac):
        connect(link, dac)
        node.emcy(EMCY_TRIP, length=5)
        wait_for(lambda: link.faults.fault is not None, "the short EMCY latched")
        assert isinstance(link.faults.fault, ProtocolError) and "expected 8" in str(
            link.faults.fault
        )


def test_a_7_byte_sdo_answer_fails_the_transfer_as_a_bad_answer(channel):
    """Item 12: it latched, but the transfer still waited for its deadline and said 'no answer'."""
    # a reply deadline no transfer here may reach
    with module_and_host(channel, reply_timeout_s=30.0) as (node, link, dac):
        connect(link, dac)
        node.short_sdo = True
        with pytest.raises(ProtocolError, match="bad SDO answer|7 data bytes"):
            dac.node.read(0x1018, 2, check_faults=False)
        assert isinstance(link.faults.fault, ProtocolError)


def test_a_download_answer_naming_another_object_is_a_bad_answer(channel):
    """Item 12: the canopen package checks an upload's answer, not a download's."""
    with module_and_host(channel) as (node, link, dac):
        connect(link, dac)
        node.other_object = True
        with pytest.raises(ProtocolError, match=r"names object 0x6412:1, not the 0x6411:1 asked"):
            dac.node.write(0x6411, 1, 0, check_faults=False)


def test_the_hosts_abort_frame_names_the_transfers_object(channel):
    """Item 12: CiA 301's abort carries the object of the transfer (the package sent 0x0000:00)."""
    with module_and_host(channel, reply_timeout_s=0.2) as (node, link, dac):
        connect(link, dac)
        node.mute_sdo = True
        with pytest.raises(DeviceTimeout):
            dac.node.read(0x1018, 2, check_faults=False)

        def aborts() -> list:
            return [
                m.data
                for m in node.received
                if m.arbitration_id == 0x600 + TORQUER and m.data[0] == 0x80
            ]

        wait_for(aborts, "the host's abort frame")
        assert bytes(aborts()[-1][1:4]) == bytes([0x18, 0x10, 2])


def swapped_xy() -> dict:
    objects = dict(AO_401_OBJECTS)
    objects[(0x1600, 1)], objects[(0x1600, 2)] = objects[(0x1600, 2)], objects[(0x1600, 1)]
    return objects


def test_a_module_whose_rpdo_swaps_x_and_y_is_mapped_per_the_eds_before_a_stream(channel):
    """Item 6: a stream meant for X drove Y to 2.5 V; only ``confirm`` saw it, afterwards."""
    with module_and_host(channel, swapped_xy()) as (node, link, dac):
        connect(link, dac)
        dac.read_scale()
        dac.configure_rpdos()
        assert [node.objects[(0x1600, s)][0] for s in range(1, 5)] == [
            0x64110110,
            0x64110210,
            0x64110310,
            0x64110410,
        ]
        dac.stream_bias_V("X", 2.5)
        wait_for(lambda: node.objects[(0x6411, 1)][0] != 0, "the RPDO applied")
        assert (
            node.objects[(0x6411, 1)][0] == round(2.5 / (10 / 32768))
            and node.objects[(0x6411, 2)][0] == 0
        )
        dac.confirm()


def test_a_module_that_keeps_another_mapping_is_refused_naming_it(channel):
    with module_and_host(channel, swapped_xy(), node_kw={"read_only": {0x1600}}) as (
        node,
        link,
        dac,
    ):
        connect(link, dac)
        dac.read_scale()
        with pytest.raises(
            ProtocolError, match=r"RPDO1 .*(refused|does not keep).*0x64110210, 0x64110110"
        ):
            dac.configure_rpdos()


def test_a_second_host_on_the_bus_is_refused_before_it_sends(channel):
    """B: another host's heartbeat on the bus: this one refuses and sends not one frame."""
    other = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
    spy = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
    task = other.send_periodic(
        can.Message(arbitration_id=0x77F, data=[5], is_extended_id=False), 0.1
    )
    try:
        time.sleep(0.15)
        while spy.recv(timeout=0) is not None:
            pass
        bus = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
        with pytest.raises(RigBusy, match="another host is driving this bus"):
            CanLink(bus, ["torquer"], channel=channel, listen_s=0.3)
        ours = [m for m in iter(lambda: spy.recv(timeout=0.05), None) if m.arbitration_id != 0x77F]
        assert ours == []
    finally:
        task.stop()
        other.shutdown()
        spy.shutdown()


HOLDER = """
import sys, time
from drivers.claim import RigClaim
claim = RigClaim("serial:///dev/ttyX?can=socketcan:can9", [("adc", sys.argv[1]), ("can", "socketcan:can9")])
print("held", flush=True)
sys.stdin.readline()
"""


def test_a_rig_held_by_another_command_is_refused_naming_it(tmp_path, monkeypatch):
    """B: the lock names its holder (pid, command, since); the holder's end frees it, however it ends."""
    monkeypatch.setenv("FBS_LOCK_DIR", str(tmp_path / "locks"))
    port = tmp_path / "ttyX"
    port.touch()
    with subprocess.Popen(
        [sys.executable, "-c", HOLDER, str(port)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
        env=os.environ | {"PYTHONPATH": os.getcwd()},
    ) as holder:
        try:
            assert holder.stdout is not None and holder.stdout.readline().strip() == "held"
            with pytest.raises(RigBusy) as err:
                RigClaim(
                    "serial:///dev/ttyX?can=socketcan:can9",
                    [("adc", str(port)), ("can", "socketcan:can9")],
                )
            assert f"pid {holder.pid} (" in str(err.value) and "since 20" in str(err.value)
            assert "sent nothing" in str(err.value)
        finally:
            holder.kill()  # SIGKILL: no clean-up of its own
            holder.wait()
    with RigClaim("u", [("adc", str(port)), ("can", "socketcan:can9")]):
        pass  # the kernel dropped the dead holder's lock


def test_the_adc_port_is_opened_exclusively(tmp_path):
    """B: a second open of the ADC's port fails before a byte is written."""
    import serial

    from drivers.serial_adc import SerialAdc

    master, slave = os.openpty()
    path = os.ttyname(slave)
    first = serial.Serial(path, exclusive=True)
    try:
        with pytest.raises(RigBusy, match="held by another program"):
            SerialAdc(path)
        os.set_blocking(master, False)
        with pytest.raises(BlockingIOError):
            os.read(master, 64)  # nothing reached the device
    finally:
        first.close()
        os.close(master)
        os.close(slave)


def test_the_emcy_frame_of_the_module_is_what_ci_a_301_says():
    """The raw node's EMCY is CiA 301's layout (a check on the test double itself)."""
    data = struct.pack("<HB5s", EMCY_TRIP, 0x11, bytes(5))
    assert len(data) == 8 and data[:3] == bytes([0x30, 0x81, 0x11])
