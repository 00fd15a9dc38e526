"""The rig's extra CAN devices, one module each (``docs/procedures/writing.md``, "A device").

The five nodes every rig has (relay driver, caging switches, torquer and command DACs, table)
are ``drivers.rig_nodes.NODES``. Any other CANopen device is a module in this package that
defines ``DEVICE``, a :class:`Device`, with its EDS file beside it (``<module>.eds``).
``catalogue()`` finds them by scanning the package, and ``drivers.rig.assemble`` connects each
one with the core nodes, builds its driver and hands it out as ``rig.devices[name]``; the
simulated rig serves the node from ``simhw.devices``. So adding a device edits no list.
"""

from __future__ import annotations

import importlib
import pkgutil
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from drivers.can_link import CanLink


class DeviceError(ValueError):
    """A device module that breaks the catalogue's rules (module docstring)."""


@dataclass(frozen=True)
class Device:
    """One CANopen device: its name (the module's), node id, product code (0x1018 sub 2, as
    its EDS says) and its driver, built from the rig's CAN link; the driver's ``node`` is its
    ``drivers.canopen_client.CanopenClient``."""

    name: str
    node_id: int
    product_code: int
    driver: Callable[[CanLink], Any] = field(repr=False)
    #: the EDS file, set by ``catalogue`` (``<module>.eds`` beside the module)
    eds: Path = Path()


def catalogue(package: str = __name__) -> dict[str, Device]:
    """Every device of ``package`` (this one unless a test names another), by name; a module
    named otherwise than its device, an EDS missing or a node id the rig already uses raise
    ``DeviceError``."""
    from drivers.rig_nodes import NODES  # a device module imports what imports this

    found: dict[str, Device] = {}
    pkg = importlib.import_module(package)
    for info in pkgutil.iter_modules(pkg.__path__):
        module = importlib.import_module(f"{package}.{info.name}")
        device = getattr(module, "DEVICE", None)
        if not isinstance(device, Device):
            continue
        where = Path(str(module.__file__))
        if device.name != info.name:
            raise DeviceError(
                f"{where}: its device is named {device.name!r}: name the module for it"
            )
        eds = where.with_suffix(".eds")
        if not eds.is_file():
            raise DeviceError(f"{where}: no EDS file beside it ({eds.name})")
        taken = dict(NODES) | {d.name: d.node_id for d in found.values()}
        clash = [n for n, i in taken.items() if i == device.node_id or n == device.name]
        if clash or not 1 <= device.node_id <= 126:
            raise DeviceError(
                f"{where}: node id {device.node_id} must be 1..126 and unused "
                f"(used: {', '.join(f'{n} {i}' for n, i in sorted(taken.items()))})"
            )
        found[device.name] = Device(
            device.name, device.node_id, device.product_code, device.driver, eds
        )
    return dict(sorted(found.items()))
