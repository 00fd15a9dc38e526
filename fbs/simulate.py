"""``fbs simulate``: the plant offline, in virtual time, no drivers (DESIGN.md section 7)."""

from __future__ import annotations

import logging
from pathlib import Path

from daq.runfile import RunWriter, check_request
from simhw.params import SimConfig, to_dict
from simhw.plant import CHANNELS, TRUTH_CHANNELS
from simhw.simulator import Simulator

log = logging.getLogger(__name__)


#: the plant's ZOH loop at this output rate already runs far slower than real time
MAX_RATE_HZ = 100_000.0


def simulate_to_file(cfg: SimConfig, out: str | Path, *, mode: int, duration_s: float, rate_hz: float,
                     seed: int = 0, truth: bool = False, effects: list[str] | None = None,
                     block_s: float = 10.0, overwrite: bool = False) -> Path:
    """Simulate ``duration_s`` seconds and write an "fbs-run" file; returns its path. The request
    is checked first (``daq.runfile.check_request``): an existing ``out`` is replaced only with
    ``overwrite``."""
    check_request(out, duration_s=duration_s, rate_hz=rate_hz, max_rate_hz=MAX_RATE_HZ,
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
