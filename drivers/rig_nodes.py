"""The rig's CAN nodes: their ids, product codes, and what the relay node's objects hold.

Every node is a CANopen device (CiA 301; ``docs/protocol.md`` section 2, ``docs/canopen-plan.md``):
relay driver 1, caging switches 2, torquer DACs 3, command DACs 4, motorized table 5; the host
is node 127 (``drivers.canopen_frames``). The relay node keeps the mode logic, the interlocks
and the clamp; its status word (object 0x2004) and interlock reasons (0x2003) are laid out
here, bit for bit, for the driver and the simulated node alike. Any further CANopen device is a
module of ``drivers.devices``: ``node_ids()`` and ``product_codes()`` hold the five and those.
"""

from __future__ import annotations

# Node ids and what each one is.
NODES = {"relay": 1, "caging": 2, "torquer": 3, "command": 4, "table": 5}
NODE_NAMES = {v: k for k, v in NODES.items()}
#: product codes (0x1018 sub 2) of the rig's own nodes; a commercial module has its own
PRODUCT_CODES = {"relay": 0x11, "caging": 0x12, "torquer": 0x13, "command": 0x14, "table": 0x15}


def node_ids() -> dict[str, int]:
    """Every node's id by name: the five above, then each device of ``drivers.devices``."""
    from drivers.devices import catalogue  # its modules import this one

    return NODES | {d.name: d.node_id for d in catalogue().values()}


def product_codes() -> dict[str, int]:
    """Every node's product code by name, as ``node_ids``."""
    from drivers.devices import catalogue

    return PRODUCT_CODES | {d.name: d.product_code for d in catalogue().values()}


# Relay driver status word (0x2004) bits.
ST_MODE_SHIFT, ST_SELECT_SHIFT = 0, 3
ST_HELD, ST_ALARM = 1 << 6, 1 << 7
ST_AT_SPEED_SHIFT, ST_CAGED_SHIFT, ST_SPIN_SHIFT = 8, 12, 16
#: the platform is clamped and its motor drive open (bits 16-23 are the spin percentage)
ST_CLAMPED = 1 << 24
#: Interlock reason bits (0x2003) of a refused RELEASE or CLAMP.
WHY_NOT_AT_SPEED, WHY_NOT_CAGED = 0x1, 0x2
#: RELEASE of mode 4, 5 or 6 while clamped; CLAMP outside modes 1-3; CLAMP or unclamp with a
#: command input (V_Td or gamma_c) not at zero
WHY_CLAMPED, WHY_MODE, WHY_COMMAND = 0x4, 0x8, 0x10
#: Modes the platform may be clamped in (the loops do not need it to move)
CLAMP_MODES = (1, 2, 3)

#: table angles travel in micro-degrees
MICRO = 1e6


def to_micro(value: float) -> int:
    return int(round(value * MICRO))


def from_micro(value: int) -> float:
    return value / MICRO
