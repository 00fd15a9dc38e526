"""``fbs simulate``: the plant offline, in virtual time, no drivers (DESIGN.md section 7),
and the Mode-3 summary that ``fbs demo`` prints until the procedures exist."""

from __future__ import annotations

import logging
from dataclasses import asdict, dataclass
from pathlib import Path

from fbs.daq.reader import read_channels
from fbs.daq.runfile import RunWriter
from fbs.daq.spectra import band_rms, dip_frequency, psd
from fbs.simhw.params import SimConfig, to_dict
from fbs.simhw.plant import CHANNELS, TRUTH_CHANNELS
from fbs.simhw.simulator import Simulator

log = logging.getLogger(__name__)


def simulate_to_file(cfg: SimConfig, out: str | Path, *, mode: int, duration_s: float, rate_hz: float,
                     seed: int = 0, truth: bool = False, effects: list[str] | None = None,
                     block_s: float = 10.0) -> Path:
    """Simulate ``duration_s`` seconds and write an "fbs-run" file; returns its path."""
    if duration_s <= 0:
        raise ValueError(f"duration {duration_s} s must be > 0")
    sim = Simulator(cfg, rate_hz=rate_hz, seed=seed, mode=mode, truth=truth)
    units = {c: "V" for c in CHANNELS} | ({t: "rad" for t in TRUTH_CHANNELS} if truth else {})
    meta = {"configuration": to_dict(cfg), "seed": seed, "effects": effects or [],
            "calibration": {}, "source": "fbs simulate (virtual time, no drivers)"}
    # a simulation is reproducible from its seed and config, so an old output may be replaced
    with RunWriter(out, rig="sim-offline", mode=mode, rate_hz=rate_hz, channels=units, meta=meta,
                   overwrite=True) as w:
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


@dataclass
class Mode3Summary:
    """What a Mode-3 record says about the platform (Ch. V E)."""

    duration_s: float
    rate_hz: float
    ac_x_ctl_rms_urad: float
    ac_y_ctl_rms_urad: float
    dip_x_hz: float
    dip_y_hz: float
    true_rms_x_urad: float | None
    true_rms_y_urad: float | None
    gyro_deduced_rms_x_urad: float
    gyro_deduced_rms_y_urad: float
    torquer_mean_V: dict

    def lines(self) -> list[str]:
        d = asdict(self)
        out = [f"Mode 3, {self.duration_s:.0f} s at {self.rate_hz:g} Hz"]
        for k, v in d.items():
            if k in ("duration_s", "rate_hz"):
                continue
            if isinstance(v, dict):
                v = ", ".join(f"{c} {x:+.4f}" for c, x in v.items())
            elif isinstance(v, float):
                v = f"{v:.3f}"
            out.append(f"  {k:26s} {v}")
        return out


def summarize_mode3(path: str | Path, cfg: SimConfig) -> Mode3Summary:
    """Dips of the control-channel spectra, and the platform rms two ways (Ch. V E.1-2):
    the truth in 0.4-200 Hz (when recorded) and the thesis's estimate, the gyro pickoff
    spectrum integrated over 0.4-15 Hz."""
    data, fs = read_channels(path)
    kac = {a: cfg.autocollimator[a].control_scale_mV_per_urad * 1e-3 for a in "XY"}  # V/urad
    kg = {a: cfg.gyro[a].pickoff_scale_mV_per_urad * 1e-3 for a in "XY"}
    res = {}
    for a in "XY":
        f, p = psd(data[f"ac_{a.lower()}_ctl"], fs)
        res[f"dip_{a}"] = dip_frequency(f, p)
        res[f"ac_{a}"] = float(data[f"ac_{a.lower()}_ctl"].std() / kac[a])
        fg, pg = psd(data[f"gyro_{a.lower()}"] / kg[a], fs)
        res[f"gyro_{a}"] = band_rms(fg, pg, 0.4, 15.0)
        th = data.get(f"theta_{a.lower()}")
        if th is not None:
            ft, pt = psd(th * 1e6, fs)
            res[f"true_{a}"] = band_rms(ft, pt, 0.4, 200.0)
    n = len(data["ac_x_ctl"])
    return Mode3Summary(n / fs, fs, res["ac_X"], res["ac_Y"], res["dip_X"], res["dip_Y"],
                        res.get("true_X"), res.get("true_Y"), res["gyro_X"], res["gyro_Y"],
                        {c: float(data[f"torq_{c}"].mean()) for c in ("x", "y", "z", "xrd")})
