"""The simulated rig's extra CAN devices: for each device of ``drivers.devices``, a module here
of the same name that defines ``NODE``, its simulated node (a ``simhw.canopen_nodes.
CanopenSimNode`` subclass that serves the device's EDS and reaches the physics, if it does,
through ``server.submit``). ``simhw.can_nodes.CanNodeHost`` puts every one on the sim's bus
with the core nodes; ``catalogue()`` finds them by scanning the package, so adding one edits
no list (``docs/procedures/writing.md``, "A device")."""

from __future__ import annotations

import importlib
import pkgutil
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from simhw.canopen_nodes import CanopenSimNode


def catalogue(package: str = __name__) -> dict[str, type[CanopenSimNode]]:
    """Every simulated device node of ``package`` (this one unless a test names another), by
    name; a module named otherwise than its node raises ``ValueError``."""
    found: dict[str, type[CanopenSimNode]] = {}
    pkg = importlib.import_module(package)
    for info in pkgutil.iter_modules(pkg.__path__):
        module = importlib.import_module(f"{package}.{info.name}")
        node = getattr(module, "NODE", None)
        if node is None:
            continue
        if node.name != info.name:
            raise ValueError(
                f"{module.__file__}: its node is named {node.name!r}: name the module for it"
            )
        found[node.name] = node
    return dict(sorted(found.items()))
