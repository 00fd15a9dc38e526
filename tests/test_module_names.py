"""A module's file name says what it is, once: no two modules of the packages share a basename.

The rule (issue 40 item 4). Across the packages of ``[tool.importlinter] root_packages``
(``fbs``, ``console``, ``procedures``, ``daq``, ``simhw``, ``drivers``), two modules may have the
same file name only in these patterns:

1. ``__init__.py`` (every package has one);
2. an ``fbs`` subcommand module: ``fbs/X.py`` is named for the command ``fbs X`` that it
   defines (``fbs.cli.COMMANDS``), a name the command line fixes, so it does not count; the
   modules it runs are named for what they are;
3. the procedure trio: a procedure ``X`` is ``procedures/calibrations/X.py`` (its steps),
   ``procedures/analysis/X.py`` (its numerics) and ``procedures/reports/X.py`` (its report),
   each at most once and only in those three folders;
4. the device pair: a CAN device ``X`` is ``drivers/devices/X.py`` (its driver) and
   ``simhw/devices/X.py`` (its simulated node), ``docs/procedures/writing.md``.

Anything else - two ``spectra.py`` in two layers, two ``lines.py`` in one - makes a reader ask
which one an import means; name the new module for what it is and for its layer instead
(``console/spectra_view.py``, ``simhw/virtual_clock.py``).
"""

from __future__ import annotations

import tomllib
from collections import defaultdict
from collections.abc import Iterable
from pathlib import Path, PurePosixPath

from fbs.cli import COMMANDS

ROOT = Path(__file__).resolve().parents[1]
TRIO = ("procedures/calibrations", "procedures/analysis", "procedures/reports")
DEVICE = ("drivers/devices", "simhw/devices")


def packages() -> list[str]:
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())
    return list(config["tool"]["importlinter"]["root_packages"])


def modules(roots: Iterable[str]) -> list[PurePosixPath]:
    """Every module file of ``roots`` (paths relative to the repository)."""
    return sorted(
        PurePosixPath(p.relative_to(ROOT).as_posix())
        for root in roots
        for p in (ROOT / root).rglob("*.py")
        if "__pycache__" not in p.parts
    )


def subcommand_modules() -> set[PurePosixPath]:
    return {PurePosixPath(c.module.replace(".", "/") + ".py") for c in COMMANDS.values()}


def name_clashes(
    paths: Iterable[PurePosixPath], subcommands: set[PurePosixPath]
) -> dict[str, list[str]]:
    """The basenames shared outside the allowed patterns (module docstring), with their paths."""
    by_name: dict[str, list[PurePosixPath]] = defaultdict(list)
    for p in paths:
        if p.name != "__init__.py" and p not in subcommands:
            by_name[p.name].append(p)
    clashes = {}
    for name, ps in by_name.items():
        if len(ps) < 2:
            continue
        folders = [str(p.parent) for p in ps]
        trio = (
            all(f in TRIO for f in folders)
            and len(set(folders)) == len(folders)
            and PurePosixPath(TRIO[0], name) in ps
        )
        if not trio and sorted(folders) != sorted(DEVICE):
            clashes[name] = [str(p) for p in ps]
    return clashes


def test_no_two_modules_share_a_name_outside_the_allowed_patterns():
    found = modules(packages())
    assert len(found) > 100 and PurePosixPath("fbs/cli.py") in found
    assert name_clashes(found, subcommand_modules()) == {}


def test_the_subcommand_modules_are_fbs_modules_that_exist():
    subcommands = subcommand_modules()
    assert PurePosixPath("fbs/spectra.py") in subcommands
    assert all(p.parts[0] == "fbs" and (ROOT / p).is_file() for p in subcommands)


def test_the_rule_refuses_a_new_duplicate_and_keeps_the_patterns():
    p = PurePosixPath
    subcommands = {p("fbs/spectra.py")}
    allowed = [
        p("daq/__init__.py"),
        p("console/__init__.py"),
        p("fbs/spectra.py"),
        p("procedures/analysis/channel_spectra.py"),
        p("procedures/calibrations/drift.py"),
        p("procedures/analysis/drift.py"),
        p("procedures/reports/drift.py"),
        p("procedures/calibrations/survey.py"),
        p("procedures/reports/survey.py"),
    ]
    assert name_clashes(allowed, subcommands) == {}
    device = [p("drivers/devices/heater.py"), p("simhw/devices/heater.py")]
    assert name_clashes([*allowed, *device], subcommands) == {}
    # two layers, one name
    assert name_clashes([*allowed, p("daq/spectra.py"), p("console/spectra.py")], subcommands) == {
        "spectra.py": ["daq/spectra.py", "console/spectra.py"]
    }
    # one layer, one name in a subfolder
    assert name_clashes(
        [p("procedures/analysis/lines.py"), p("procedures/analysis/gap/lines.py")], subcommands
    ) == {"lines.py": ["procedures/analysis/lines.py", "procedures/analysis/gap/lines.py"]}
    # a trio name outside the trio's folders, or without a procedure of that name
    assert "drift.py" in name_clashes([*allowed, p("daq/drift.py")], subcommands)
    assert "fit.py" in name_clashes(
        [p("procedures/analysis/fit.py"), p("procedures/reports/fit.py")], subcommands
    )
    # an fbs module that is no subcommand counts
    assert "progress.py" in name_clashes(
        [p("fbs/progress.py"), p("procedures/progress.py")], subcommands
    )
