"""The sim rig's virtual channel: frames reach the simulated nodes in the sender's thread, with
the bytes sent, and reach any other receiver as python-can's own copy."""

from __future__ import annotations

import uuid

import can
import canopen

from simhw.can_nodes import InlineVirtualBus, _deliver_inline


def test_inline_bus_hands_the_nodes_the_bytes_and_others_a_copy() -> None:
    channel = f"test-inline-{uuid.uuid4().hex}"
    nodes = canopen.Network(can.Bus(interface="virtual", channel=channel))
    _deliver_inline(nodes)
    got: list[tuple[int, bytes, float]] = []
    nodes.subscribe(0x201, lambda can_id, data, ts: got.append((can_id, bytes(data), ts)))
    other = can.Bus(interface="virtual", channel=channel)
    host = InlineVirtualBus(channel=channel, receive_own_messages=False)
    try:
        msg = can.Message(
            arbitration_id=0x201, data=bytearray(b"\x01\x02\x03"), is_extended_id=False
        )
        host.send(msg)
        # handled before send returned, in this thread, with the bytes as sent
        assert [(i, d) for i, d, _ in got] == [(0x201, b"\x01\x02\x03")]
        msg.data[0] = 0xFF  # the sender's message is its own: nothing received changes
        assert got[0][1] == b"\x01\x02\x03"
        copy = other.recv(timeout=1.0)
        assert copy is not None and copy is not msg
        assert (copy.arbitration_id, bytes(copy.data), copy.is_rx) == (0x201, b"\x01\x02\x03", True)
        assert copy.timestamp == got[0][2]  # one timestamp for every receiver
        # a remote frame is no data for a CANopen listener, inline or not
        host.send(can.Message(arbitration_id=0x201, is_remote_frame=True, is_extended_id=False))
        assert len(got) == 1
        assert other.recv(timeout=1.0) is not None
        assert host.recv(timeout=0) is None  # not its own frames
    finally:
        host.shutdown()
        other.shutdown()
        nodes.bus.shutdown()
