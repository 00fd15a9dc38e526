"""The scripted procedures, one module each; a module is a procedure if it defines
``PROCEDURE`` (a ``procedures.runner.Procedure`` subclass). ``catalogue()`` finds them
by scanning this package, so adding one touches nothing else."""

from __future__ import annotations

import importlib
import pkgutil
from typing import TYPE_CHECKING

if TYPE_CHECKING:   # module_names() must not load the runner (numpy, h5py): fbs's parser calls it
    from procedures.runner import Procedure


def catalogue() -> dict[str, type[Procedure]]:
    found: dict[str, type[Procedure]] = {}
    for info in pkgutil.iter_modules(__path__):
        module = importlib.import_module(f"{__name__}.{info.name}")
        proc = getattr(module, "PROCEDURE", None)
        if proc is not None:
            found[proc.name] = proc
    return dict(sorted(found.items()))


def module_names() -> list[str]:
    """The procedure modules' names, without importing them."""
    return sorted(info.name for info in pkgutil.iter_modules(__path__))


def get(name: str) -> type[Procedure]:
    procs = catalogue()
    if name not in procs:
        raise ValueError(f"unknown procedure {name!r} (known: {', '.join(procs)})")
    return procs[name]
