"""The scripted procedures, one module each; a module is a procedure if it defines
``PROCEDURE`` (a ``procedures.procedure.Procedure`` subclass). ``catalogue()`` finds them
by scanning this package, so adding one touches nothing else. A procedure's module is named
for it (``earth-rate`` in ``earth_rate.py``): the command line lists the procedures by module
name without importing them (``module_names``), so ``catalogue()`` refuses a module whose
procedure is named otherwise (``CatalogueError``), and a test runs it over this package."""

from __future__ import annotations

import importlib
import pkgutil
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # module_names() must not load the runner (numpy, h5py): fbs's parser calls it
    from procedures.procedure import Procedure


class CatalogueError(Exception):
    """A procedure module that breaks the catalogue's rule (module docstring)."""


def module_name(procedure_name: str) -> str:
    """The module a procedure named ``procedure_name`` lives in."""
    return procedure_name.replace("-", "_")


def catalogue(package: str = __name__) -> dict[str, type[Procedure]]:
    """Every procedure of ``package`` (this one unless a test names another), by name."""
    found: dict[str, type[Procedure]] = {}
    pkg = importlib.import_module(package)
    for info in pkgutil.iter_modules(pkg.__path__):
        module = importlib.import_module(f"{package}.{info.name}")
        proc = getattr(module, "PROCEDURE", None)
        if proc is None:
            continue
        if module_name(proc.name) != info.name:
            raise CatalogueError(
                f"{module.__file__}: its procedure is named {proc.name!r}, but a procedure's module is its "
                f"name with '-' as '_' ({module_name(proc.name)}.py): rename one, or `fbs run {proc.name}` "
                f"cannot find it"
            )
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
