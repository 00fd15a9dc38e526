"""The layout every tool can read (DESIGN.md section 2): each top-level folder is the package of
its own name, importable from any directory through the editable install's plain path entry,
and a static resolver (jedi, which IDEs use) follows ``open_rig`` to its definition."""

from __future__ import annotations

import subprocess
import sys
from importlib.metadata import entry_points
from pathlib import Path

import jedi

ROOT = Path(__file__).resolve().parents[1]


def test_the_packages_import_from_any_directory_as_themselves(tmp_path):
    code = (
        "import drivers.rig, daq.runfile, simhw.plant, procedures.runner, console.app, fbs.cli\n"
        "import drivers.errors as e\n"
        "print(drivers.rig.__file__); print(e.DriverError.__module__)"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, check=True
    )
    path, module = out.stdout.split()
    assert Path(path) == ROOT / "drivers" / "rig.py" and module == "drivers.errors"


def test_a_static_resolver_finds_open_rig_in_drivers_rig(tmp_path):
    script = tmp_path / "user.py"
    code = 'from drivers.rig import open_rig\nopen_rig("sim")\n'
    env = jedi.create_environment(sys.executable, safe=False)
    found = jedi.Script(code, path=script, project=jedi.Project(tmp_path), environment=env).goto(
        2, 2, follow_imports=True
    )
    assert [(Path(d.module_path), d.type, d.name) for d in found] == [
        (ROOT / "drivers" / "rig.py", "function", "open_rig")
    ]
    line = (ROOT / "drivers" / "rig.py").read_text().splitlines()[found[0].line - 1]
    assert line.startswith("def open_rig(")


def test_every_package_ships_py_typed_and_the_sim_scheme_is_an_entry_point():
    for pkg in ("fbs", "drivers", "simhw", "daq", "procedures", "console"):
        assert (ROOT / pkg / "py.typed").exists(), pkg
    sim = [ep.value for ep in entry_points(group="fbs.rig_schemes", name="sim")]
    assert sim == ["simhw.rig_scheme:open_sim_rig"]
