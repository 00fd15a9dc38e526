"""Rig URL options for the CAN bus (issue 21 item 6): bus options reach python-can, the sim's
own CAN keys are checked; nothing here opens a bus."""

from __future__ import annotations

import pytest

from drivers.rig import bus_options, open_rig


def test_bitrate_and_can_options_become_bus_options():
    params = {
        "can": "slcan:/dev/pts/7",
        "bitrate": "500000",
        "can_tty_baudrate": "115200",
        "can_receive_own_messages": "off",
        "can_poll_interval": "0.01",
        "can_serial": "A1B2",
        "table": "can",
    }
    assert bus_options("u", params) == {
        "bitrate": 500000,
        "tty_baudrate": 115200,
        "receive_own_messages": False,
        "poll_interval": 0.01,
        "serial": "A1B2",
    }


@pytest.mark.parametrize("bad", ["fast", "0", "-5", "1.5"])
def test_a_bad_bitrate_is_named(bad):
    with pytest.raises(ValueError, match=f"bitrate={bad!r} must be a positive integer"):
        bus_options("u", {"bitrate": bad})


def test_serial_url_refuses_unknown_keys_but_takes_bus_options():
    with pytest.raises(ValueError, match=r"unknown parameter\(s\) bogus"):
        open_rig("serial:///dev/null?can=virtual:x&bogus=1")


@pytest.mark.parametrize(
    "url, message",
    [
        ("sim?can=socketcan:can0", r"the sim's bus is python-can's virtual one"),
        ("sim?external=pump", r"unknown node\(s\) pump"),
        ("sim?bitrate=500000", r"unknown parameter\(s\) bitrate"),
        (
            "sim?canopen=all",
            r"unknown parameter\(s\) canopen",
        ),  # every node speaks CANopen: no choice left
    ],
)
def test_sim_url_can_keys_are_checked(url, message):
    with pytest.raises(ValueError, match=message):
        open_rig(url)
