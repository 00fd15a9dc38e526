"""``fbs simulate``: the plant offline, in virtual time, no drivers (DESIGN.md section 7)."""

from __future__ import annotations

import logging
import math
import shutil
from pathlib import Path

import h5py

from daq.runfile import STATUS_RECORDING, RunFileError, RunWriter, check_new_path
from simhw.params import SimConfig, to_dict
from simhw.plant import CHANNELS, TRUTH_CHANNELS
from simhw.simulator import Simulator

log = logging.getLogger(__name__)


#: the plant's ZOH loop at this output rate already runs far slower than real time
MAX_RATE_HZ = 100_000.0


def check_request(out: str | Path, *, duration_s: float, rate_hz: float, n_channels: int,
                  overwrite: bool = False) -> None:
    """Refuse, before anything is opened, a simulation that cannot be what was meant: a duration
    or rate that is not a finite positive number, a rate beyond ``MAX_RATE_HZ``, fewer than two
    samples, more data than the output's disk has room for, or an output that exists (unless
    ``overwrite``; even then never one a writer may still be filling). ``ValueError`` or
    ``RunFileError`` names the value and the limit."""
    for name, v in (("duration", duration_s), ("rate", rate_hz)):
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
            raise ValueError(f"--{name} {v!r} must be a finite number > 0")
    if rate_hz > MAX_RATE_HZ:
        raise ValueError(f"--rate {rate_hz:g} Hz is beyond the offline simulator's {MAX_RATE_HZ:g} Hz")
    samples = duration_s * rate_hz
    if samples < 2:
        raise ValueError(f"--duration {duration_s:g} s at --rate {rate_hz:g} Hz gives {samples:.3g} samples; "
                         f"at least 2 are needed")
    out = Path(out)
    check_new_path(out, overwrite)
    if out.exists():
        try:
            with h5py.File(out, "r") as f:
                status = str(f.attrs.get("status", ""))
        except OSError as exc:
            raise RunFileError(f"{out} cannot be opened ({exc}): perhaps a writer has it; not replaced") from None
        if status == STATUS_RECORDING:
            raise RunFileError(f"{out} has status {STATUS_RECORDING!r} (a writer may still be filling it): "
                               f"not replaced, even with --force")
    need = samples * n_channels * 8 * 1.05           # float64 per channel, a little for the layout
    free = shutil.disk_usage(out.parent).free
    if need > free:
        raise ValueError(f"--duration {duration_s:g} s at --rate {rate_hz:g} Hz needs about {need / 1e9:.3g} GB; "
                         f"{out.parent} has {free / 1e9:.3g} GB free")


def simulate_to_file(cfg: SimConfig, out: str | Path, *, mode: int, duration_s: float, rate_hz: float,
                     seed: int = 0, truth: bool = False, effects: list[str] | None = None,
                     block_s: float = 10.0, overwrite: bool = False) -> Path:
    """Simulate ``duration_s`` seconds and write an "fbs-run" file; returns its path. The request
    is checked first (``check_request``): an existing ``out`` is replaced only with ``overwrite``."""
    check_request(out, duration_s=duration_s, rate_hz=rate_hz,
                  n_channels=len(CHANNELS) + (len(TRUTH_CHANNELS) if truth else 0), overwrite=overwrite)
    sim = Simulator(cfg, rate_hz=rate_hz, seed=seed, mode=mode, truth=truth)
    units = {c: "V" for c in CHANNELS} | ({t: "rad" for t in TRUTH_CHANNELS} if truth else {})
    meta = {"configuration": to_dict(cfg), "seed": seed, "effects": effects or [],
            "calibration": {}, "source": "fbs simulate (virtual time, no drivers)"}
    with RunWriter(out, rig="sim-offline", mode=mode, rate_hz=rate_hz, channels=units, meta=meta,
                   overwrite=overwrite) as w:
        w.event(0.0, "mode", f"mode {mode}")
        for e in effects or []:
            w.event(0.0, "effect", e)
        for block in sim.run(duration_s, block_s):
            cols = {c: block[c] for c in CHANNELS}
            if truth:
                cols |= {t: block[t] for t in TRUTH_CHANNELS}
            w.append(cols)
            for j, c in enumerate(CHANNELS):
                over = block.overrange[:, j]
                if over.any():
                    first = int(over.argmax())
                    w.event(block.t0 + first / rate_hz, "overrange", f"{c}: {int(over.sum())} samples beyond range")
    return Path(out)
