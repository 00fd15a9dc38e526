"""Fixtures of the model-gap tests.

``independent`` is ``tests/procedures/analysis/gap/independent.py``, the generator of "measured" runs
that shares no code with ``simhw``. Tests run with ``--import-mode=importlib``, so a
sibling module cannot be imported by name; it is loaded here by path, once per session, and
registered in ``sys.modules`` under ``independent.MODULE_NAME`` (numba's on-disk cache
needs the name to be importable)::

    def test_gap_finds_the_bearing(independent, tmp_path):
        run = independent.generate(tmp_path / "run.h5", stiffness_Nm_per_rad=410.0, seed=3)
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

_NAME = "fbs_tests_gap_independent"  # = independent.MODULE_NAME
_PATH = Path(__file__).with_name("independent.py")


def load_independent():
    """The generator module (loaded once per process)."""
    mod = sys.modules.get(_NAME)
    if mod is None:
        spec = importlib.util.spec_from_file_location(_NAME, _PATH)
        mod = importlib.util.module_from_spec(spec)
        sys.modules[_NAME] = mod
        try:
            spec.loader.exec_module(mod)
        except BaseException:
            del sys.modules[_NAME]
            raise
    return mod


@pytest.fixture(scope="session")
def independent():
    """The independent Mode-3 generator module: ``independent.generate(path, **kw) -> Path``."""
    return load_independent()


#: ADC ranges of the hidden-effect runs, as a lab would set them for Mode-3 noise levels with
#: room for an offset jump's transient (a 50 urad swing is 0.3 V on the control channel).
HIDDEN_RANGES_V = {"ctl": 1.0, "inst": 1.0, "gyro": 1.0, "pa": 0.05}


def make_hidden(
    path: Path,
    specs: list[str] | tuple[str, ...] = (),
    *,
    seed: int = 0,
    axis: str = "X",
    duration_s: float = 300.0,
    rate_hz: float = 1000.0,
) -> Path:
    """A Mode-3 run of the axis's four channels from ``simhw``, nominal (no bearing torque)
    plus the effects ``specs`` (``name:k=v,...`` as ``fbs simulate --effect``), written as an
    fbs-run file with the axis attribute."""
    from daq.runfile import RunWriter
    from simhw import effects
    from simhw.simulator import Simulator

    cfg = effects.nominal()
    for spec in specs:
        effect, values, _ = effects.parse_spec(spec)
        cfg = effect.inject(cfg, axis, **values)
    a = axis.lower()
    channels = {f"ac_{a}_ctl": "ctl", f"ac_{a}_inst": "inst", f"gyro_{a}": "gyro", f"pa_{a}": "pa"}
    sim = Simulator(cfg, rate_hz, seed=seed, mode=3)
    for c, kind in channels.items():
        sim.set_range(c, HIDDEN_RANGES_V[kind])
    with RunWriter(
        path,
        rig="sim-offline",
        mode=3,
        rate_hz=rate_hz,
        channels=dict.fromkeys(channels, "V"),
        axis=axis,
        meta={"effects": list(specs), "seed": seed},
        overwrite=True,
    ) as w:
        for block in sim.run(duration_s, 10.0):
            w.append({c: block[c] for c in channels})
    return Path(path)


@pytest.fixture(scope="session")
def hidden():
    """``make_hidden``: simhw runs with hidden effects."""
    return make_hidden
