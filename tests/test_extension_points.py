"""Issue 40, acceptance A: adding a procedure, an effect, a device and a channel each touches
exactly the files ``docs/procedures/writing.md`` lists.

Each test takes the guide's worked example as it is written there (its ``file=`` and ``edit=``
code blocks), puts it in a temporary place - a directory added to the package's ``__path__``,
so the package's own catalogue must find it, or for a channel copies of the two packages it
edits - runs it as a user would, and checks that the files it wrote or edited are exactly the
section's checklist. A change that makes one of these need another edit (a list to extend, a
switch to add a case to) fails here.
"""

from __future__ import annotations

import importlib
import json
import os
import re
import shutil
import subprocess
import sys
from collections.abc import Iterable
from pathlib import Path, PurePosixPath

import h5py
import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
GUIDE = ROOT / "docs" / "procedures" / "writing.md"
BLOCK = re.compile(r"^```\w+ (file|edit)=(\S+)\n(.*?)^```", re.M | re.S)


def section(title: str) -> str:
    """The guide's ``## {title}`` section."""
    text = GUIDE.read_text()
    assert f"\n## {title}\n" in text, f"{GUIDE.name} has no section {title!r}"
    return text.split(f"\n## {title}\n", 1)[1].split("\n## ", 1)[0]


def checklist(text: str) -> set[str]:
    """The files a section's checklist names (``- [ ] `path`: why``)."""
    return set(re.findall(r"^- \[ \] `([^`]+)`", text, re.M))


def blocks(text: str) -> dict[str, tuple[str, str]]:
    """A section's example blocks: path -> (``file`` or ``edit``, the block's text)."""
    return {path: (kind, body) for kind, path, body in BLOCK.findall(text)}


def command(text: str, out: Path) -> list[str]:
    """The section's ``fbs`` command (its indented code line), as argv after ``fbs``, its
    ``--out`` in ``out``."""
    (line,) = re.findall(r"^    (fbs .*)$", text, re.M)
    argv = line.split()[1:]
    at = argv.index("--out") + 1
    argv[at] = str(out / argv[at])
    return argv


def names_stay_unique(files: Iterable[str]) -> None:
    """The repository's module-name rule (``tests/test_module_names.py``) holds with the
    added files in it: adding one needs no edit of the rule either."""
    from tests.test_module_names import modules, name_clashes, packages, subcommand_modules

    added = [PurePosixPath(f) for f in files if f.endswith(".py")]
    assert name_clashes([*modules(packages()), *added], subcommand_modules()) == {}


def mount(tmp: Path, monkeypatch, files: dict[str, str]) -> None:
    """Write each ``repo/path.ext`` into ``tmp`` and add its directory to the package's
    ``__path__`` (the package the path names), as if the file were in the package."""
    for rel, text in files.items():
        target = tmp / rel
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_text(text)
        package = importlib.import_module(str(Path(rel).parent).replace("/", "."))
        if str(target.parent) not in package.__path__:
            monkeypatch.setattr(package, "__path__", [*package.__path__, str(target.parent)])
        if rel.endswith(".py"):
            name = f"{package.__name__}.{Path(rel).stem}"
            # so that monkeypatch's undo drops the module the test imports
            monkeypatch.setitem(sys.modules, name, None)
            del sys.modules[name]
    importlib.invalidate_caches()


# ---------------------------------------------------------------------------- a procedure
def test_a_procedure_is_one_module_that_fbs_run_and_the_demo_find(tmp_path, monkeypatch, capsys):
    from fbs.cli import main
    from fbs.demo import campaign
    from procedures.calibrations import catalogue, module_names
    from tests.result_schema import assert_valid_result

    text = section("A procedure")
    files = {p: body for p, (kind, body) in blocks(text).items() if kind == "file"}
    assert set(files) == checklist(text) == {"procedures/calibrations/ac_noise.py"}
    names_stay_unique(files)
    mount(tmp_path / "src", monkeypatch, files)

    assert "ac_noise" in module_names() and "ac-noise" in catalogue()
    assert campaign()[-1] == ("ac-noise", None, ())  # the demo runs it, once, last
    argv = command(text, tmp_path)
    assert argv[:2] == ["run", "ac-noise"] and "--json" in argv
    out = Path(argv[argv.index("--out") + 1])
    code = main(argv)
    result = json.loads(capsys.readouterr().out)
    assert code == 0, result
    assert_valid_result(result)
    assert result["procedure"] == "ac-noise" and result["verdict"] == "pass"
    rms = result["rms_urad"]
    assert set(rms) == {"X", "Y"} and all(0 < v < 100 for v in rms.values()), rms
    assert (out / "ac-noise.h5").is_file() and (out / "ac-noise.md").is_file()


# ---------------------------------------------------------------------------- an effect
def test_an_effect_is_one_module_that_fbs_simulate_injects(tmp_path, monkeypatch):
    from daq.reader import RunFile
    from fbs.cli import main
    from simhw import effects

    text = section("An effect")
    files = {p: body for p, (kind, body) in blocks(text).items() if kind == "file"}
    assert set(files) == checklist(text) == {"simhw/effects/pickoff_hum.py"}
    names_stay_unique(files)
    mount(tmp_path / "src", monkeypatch, files)

    assert "pickoff_hum" in effects.catalogue()
    argv = command(text, tmp_path)
    assert argv[0] == "simulate" and "pickoff_hum:amplitude_V=0.05" in argv
    assert main(argv) == 0
    with RunFile(argv[argv.index("--out") + 1]) as run:
        x = run.read(["gyro_x"])[0]
    spectrum = np.abs(np.fft.rfft(x - x.mean())) * 2 / len(x)
    freqs = np.fft.rfftfreq(len(x), 1 / 500)
    assert spectrum[np.argmin(abs(freqs - 60.0))] == pytest.approx(0.05, rel=0.2)


# ---------------------------------------------------------------------------- a device
def _heater_eds(edit: str) -> str:
    """The guide's EDS: caging.eds with the lines its ``edit=`` block gives (the two
    ``DefaultValue`` lines are ``[1018sub2]``'s and ``[1008]``'s, as the guide says)."""
    lines = [ln for ln in edit.splitlines() if ln.strip()]
    keyed = {ln.split("=", 1)[0]: ln for ln in lines if not ln.startswith("DefaultValue=")}
    defaults = iter(ln for ln in lines if ln.startswith("DefaultValue="))
    where = {"[1018sub2]": next(defaults), "[1008]": next(defaults)}
    out, current = [], ""
    for ln in (ROOT / "drivers" / "eds" / "caging.eds").read_text().splitlines():
        if ln.startswith("["):
            current = ln
        key = ln.split("=", 1)[0]
        if key == "DefaultValue" and current in where:
            ln = where[current]
        elif key in keyed and current in ("[FileInfo]", "[DeviceInfo]"):
            ln = keyed[key]
        out.append(ln)
    return "\n".join(out) + "\n"


def test_a_device_is_its_driver_eds_and_simulated_node_and_answers_on_the_bus(
    tmp_path, monkeypatch
):
    from drivers import rig_nodes
    from drivers.caging import DO_8
    from drivers.errors import SetpointRangeError
    from drivers.rig import open_rig

    text = section("A device")
    found = blocks(text)
    files = {p: body for p, (kind, body) in found.items() if kind == "file"}
    files["drivers/devices/heater.eds"] = _heater_eds(found["drivers/devices/heater.eds"][1])
    assert set(found) == set(files) == checklist(text)
    names_stay_unique(files)
    mount(tmp_path / "src", monkeypatch, files)

    assert rig_nodes.node_ids()["heater"] == 6
    with open_rig("sim") as rig:
        heater = rig.devices["heater"]
        node = rig.emulator.nodes.nodes["heater"]
        assert heater.node.identify() == 0x16  # its EDS's product code, over SDO
        assert heater.switch("XZ", True) is True and node.get(DO_8, 1) == 0b10
        assert heater.switch("XY", True) is True and node.get(DO_8, 1) == 0b11
        assert heater.switch("XY", False) is False and node.get(DO_8, 1) == 0b10
        with pytest.raises(SetpointRangeError):  # the node refuses an output not wired
            heater.node.write(DO_8, 1, 0x04)
        assert rig.safe().ok and node.get(DO_8, 1) == 0b10  # safe leaves the heaters alone


# ---------------------------------------------------------------------------- a channel
#: where the guide says each ``edit=`` block goes: (the line it goes before or after, which)
CHANNEL_ANCHORS = {
    "drivers/rig_datasheet.py": ('    "cmd_z",\n)', "before_close"),
    "simhw/plant.py": ('        b.outputs[f"cmd_{a.lower()}"]', "after"),
}


def _edit(source: str, anchor: str, how: str, block: str) -> str:
    assert source.count(anchor) == 1, f"the guide's anchor {anchor!r} is not one line"
    if how == "before_close":  # inside the tuple, before its closing parenthesis
        return source.replace(anchor, anchor[:-1] + block + ")")
    at = source.index(anchor)
    end = source.index("\n", at) + 1
    return source[:end] + block + source[end:]


def test_a_channel_is_its_name_and_its_signal_and_is_recorded(tmp_path):
    text = section("A channel")
    edits = {p: body for p, (kind, body) in blocks(text).items() if kind == "edit"}
    assert set(edits) == checklist(text) == set(CHANNEL_ANCHORS)
    # copies of the packages the channel edits, ahead of the installed ones on sys.path (numba's
    # cache comes along, its stamps kept: the kernels are not compiled again)
    site = tmp_path / "site"
    for package in {Path(p).parts[0] for p in edits}:
        shutil.copytree(ROOT / package, site / package)
    for rel, block in edits.items():
        anchor, how = CHANNEL_ANCHORS[rel]
        path = site / rel
        path.write_text(_edit(path.read_text(), anchor, how, block))
    argv = command(text, tmp_path)
    assert argv[:3] == ["record", "--rig", "sim"]
    out = argv[argv.index("--out") + 1]
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    cmd = [sys.executable, "-m", "fbs", *argv]
    done = subprocess.run(cmd, cwd=site, env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-3000:]
    with h5py.File(out, "r") as f:
        for name in ("tach_x", "tach_y", "tach_z"):
            data = f["channels"][name][:]
            assert f["channels"][name].attrs["units"] == "V"
            assert len(data) > 0 and np.all(np.isfinite(data)), name


# ---------------------------------------------------------------------------- the name rule
@pytest.mark.parametrize(
    "rel, text, catalogue",
    [
        (
            "simhw/effects/hum.py",
            "from simhw.effects import Effect\nEFFECT = Effect('buzz', '', (), lambda c, a: c)\n",
            "simhw.effects:catalogue",
        ),
        (
            "drivers/devices/lamp.py",
            "from drivers.devices import Device\nDEVICE = Device('light', 7, 0x17, print)\n",
            "drivers.devices:catalogue",
        ),
        (
            "simhw/devices/lamp.py",
            "from simhw.canopen_nodes import CanopenSimNode\n"
            "class Light(CanopenSimNode):\n    name = 'light'\nNODE = Light\n",
            "simhw.devices:catalogue",
        ),
    ],
)
def test_a_module_named_otherwise_than_what_it_defines_is_refused(
    tmp_path, monkeypatch, rel, text, catalogue
):
    """The guide's rule (each module named for what it defines; the command line and a reader
    find it by that name) is the catalogue's, not a convention."""
    mount(tmp_path, monkeypatch, {rel: text})
    module, name = catalogue.split(":")
    with pytest.raises(ValueError, match=r"name the module for it"):
        getattr(importlib.import_module(module), name)()
