"""Hysteresis sweeps recorded "by another system" (issue 38 item 7): files the procedure never wrote.

``write_smooth_sweep`` drives the offline simulator's plant (``simhw.Simulator``, Mode 3, the
gimbal bearing Dahl's model of eq. 5.2 with the given To and eta) by a *smooth* sinusoidal
autocollimator bias - the bias is set anew at every output sample, so the command carries no
DAC staircase and no line but its fundamental - through a ladder of amplitudes that change at
the command's zero crossings. The run is written with plain h5py in the "fbs-run" layout of
DESIGN.md section 6 and nothing of ours (no ``RunWriter``, no procedure, no events): float32
channels in chunks and compression of its own, the power-amplifier input on a range of its own,
the rig's data sheet in ``/meta/calibration`` or not at all. The simulator's noise (the
autocollimator's white and 1/f noise, fed through the servo; the recorder's anti-alias filter
and ADC) is all there.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
from collections.abc import Sequence
from datetime import UTC, datetime
from pathlib import Path

import h5py
import numpy as np

from simhw.config import SimConfig
from simhw.datasheet import rig_calibration
from simhw.simulator import Simulator

#: output samples simulated a call
BLOCK = 2000


def _set_bias(axis: str, volts: float, sim: Simulator) -> None:
    sim.set_ac_bias_V(axis, volts)


def write_smooth_sweep(
    path: str | Path,
    *,
    To_Nm: float = 0.016,
    eta_per_Nm: float = 1.6e6,
    axis: str = "X",
    freq_hz: float = 0.4,
    amplitudes_urad: Sequence[float] = (600, 300, 120, 60, 30, 12, 6),
    cycles: int = 6,
    rate_hz: float = 400.0,
    seed: int = 11,
    lead_s: float = 3.0,
    pa_range_V: float = 0.5,
    meta_calibration: bool = True,
    chunk: int = 3000,
    compression: str | None = "gzip",
    nea_scale: float = 1.0,
    inertia_scale: float = 1.0,
    bearing_model: str = "dahl",
    stiffness_Nm_per_rad: float = 410.0,
    damping_Nms: float = 0.05,
    updates_per_cycle: int = 0,
    internal_rate_hz: float | None = None,
) -> Path:
    """Write the sweep; return its path. ``bearing_model`` (DESIGN.md section 7's sim config:
    "dahl" with ``To_Nm``, ``eta_per_Nm``; "none"; "viscous" with ``damping_Nms``; "spring"
    with ``stiffness_Nm_per_rad``) is the swept axis's bearing. ``nea_scale`` scales the autocollimator's noise,
    ``inertia_scale`` the swept axis's inertia; ``updates_per_cycle`` > 0 makes the command a
    DAC staircase of that many steps a cycle (as our procedure's), for comparison (the data sheet
    in ``/meta/calibration`` follows the rig)."""
    a = axis.upper()
    cfg = SimConfig()
    cfg.bearing[a].model = bearing_model
    cfg.bearing[a].stiffness_Nm_per_rad = float(stiffness_Nm_per_rad)
    cfg.bearing[a].damping_Nms = float(damping_Nms)
    cfg.bearing[a].To_Nm = float(To_Nm)
    cfg.bearing[a].eta_per_Nm = float(eta_per_Nm)
    cfg.autocollimator[a].nea_urad *= nea_scale
    cfg.platform[a].inertia_kg_m2 *= inertia_scale
    if internal_rate_hz is not None:
        cfg.sampling.min_internal_rate_hz = float(internal_rate_hz)
    names = [f"cmd_{a.lower()}", f"ac_{a.lower()}_inst", f"pa_{a.lower()}", f"ac_{a.lower()}_ctl"]
    sim = Simulator(cfg, rate_hz=rate_hz, seed=seed, mode=3, spin=1.0, channels=names)
    sim.set_range(names[2], pa_range_V)
    volts_per_rad = cfg.autocollimator[a].control_scale_mV_per_urad * 1e-3 / 1e-6
    n_lead = int(round(lead_s * rate_hz))
    n_sweep = int(round(len(amplitudes_urad) * cycles * rate_hz / freq_hz))
    # the amplitude of each sample: constant over whole cycles, changed at the zero crossings
    t = (np.arange(n_sweep) + 0.5) / rate_hz
    step = np.minimum((t * freq_hz // cycles).astype(int), len(amplitudes_urad) - 1)
    phase = freq_hz * t
    if updates_per_cycle:  # a DAC staircase instead (as our procedure drives), for comparison
        phase = (np.floor(phase * updates_per_cycle) + 0.5) / updates_per_cycle
    bias = (
        -np.asarray(amplitudes_urad, float)[step]
        * 1e-6
        * volts_per_rad
        * np.sin(2 * math.pi * phase)
    )
    bias = np.concatenate([np.zeros(n_lead), bias, np.zeros(int(round(rate_hz / freq_hz)))])
    # the bias set before every sample, as set-point events in blocks: the same samples, to
    # the bit, as an ``advance(1)`` a sample (``Simulator.advance``), at a fraction of the calls
    out = np.empty((len(bias), len(names)))
    for k0 in range(0, len(bias), BLOCK):
        part = bias[k0 : k0 + BLOCK]
        events = [(i, functools.partial(_set_bias, a, float(v))) for i, v in enumerate(part)]
        out[k0 : k0 + len(part)] = sim.advance(len(part), events, setpoints=True).volts
    path = Path(path)
    with h5py.File(path, "w", libver=("earliest", "v110")) as f:
        f.attrs["format"] = "fbs-run"
        f.attrs["format_version"] = 1
        f.attrs["created"] = datetime.now(UTC).isoformat()
        f.attrs["rig"] = "another lab's recorder"
        f.attrs["mode"] = 3
        g = f.create_group("channels")
        for j, name in enumerate(names):
            d = g.create_dataset(
                name,
                data=out[:, j].astype(np.float32),
                chunks=(min(chunk, len(out)),),
                compression=compression,
            )
            d.attrs["units"] = "V"
            d.attrs["sample_rate_hz"] = float(rate_hz)
        if meta_calibration:
            f.create_group("meta").attrs["calibration"] = json.dumps(
                dataclasses.asdict(rig_calibration(cfg))
            )
    return path
