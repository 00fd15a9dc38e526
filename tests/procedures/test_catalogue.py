"""The procedure catalogue's rule (issue 40 item 1): a procedure lives in the module named for it."""

from __future__ import annotations

import pytest

from procedures.calibrations import CatalogueError, catalogue, module_name, module_names


def test_every_procedure_lives_in_the_module_named_for_it():
    # what the command line lists without importing is what it can run
    assert set(module_names()) == {module_name(n) for n in catalogue()}


def _package(root, name: str, modules: dict[str, str]) -> None:
    pkg = root / name
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    for mod, proc_name in modules.items():
        (pkg / f"{mod}.py").write_text(f"class P:\n    name = {proc_name!r}\n\n\nPROCEDURE = P\n")


def test_a_renamed_procedure_is_refused_by_name(tmp_path, monkeypatch):
    monkeypatch.syspath_prepend(str(tmp_path))
    _package(tmp_path, "procs_ok", {"earth_rate": "earth-rate", "notes": "notes"})
    assert sorted(catalogue("procs_ok")) == ["earth-rate", "notes"]
    _package(tmp_path, "procs_renamed", {"earth_rate": "earth-rate", "old_name": "new-name"})
    with pytest.raises(
        CatalogueError, match=r"old_name\.py: its procedure is named 'new-name'.*\(new_name\.py\)"
    ):
        catalogue("procs_renamed")
