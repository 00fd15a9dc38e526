"""Coverage of the baseline procedure's 95 % intervals on drawn rigs (issue 38 item 5).

Each rig is drawn beyond the nominal unit of DESIGN.md section 8 and the thesis values: the axis
X or Y; the autocollimator's NEA x0.6..1.6, its 1/f corner 1.5..5 Hz, the knee's form anywhere
between ``max(1, fc/f)`` and ``1 + fc/f`` (half the rigs the thesis's ``1 + fc/f``), slope
0.8..1.2, a common X/Y noise part 0..0.6; the azimuth NEA x0.6..1.6; the pickoff's rms x0.5..2,
its lines each +-1 Hz and x0.5..2. The clamped record (the default 480 s at 1 kHz) is made by the
offline simulator (``simhw.simulator.Simulator``, mode 3, clamped, only the four channels read)
and analysed by the procedure's own numerics (``procedures.analysis.baseline.baseline_figures``).

The truth of each figure is the simulator's: the NEA and the band rms from the noise sources'
exact spectra through the channel's filter (``Sources.spectrum``; the anti-alias filter is the
recorder's, not the sensor's), the white level ``sqrt(W)`` and the corner ``flicker_corner_hz``.

Prints per figure: n, covered, median and max |relative error|, unresolved share.
Usage: ``python bench/baseline_coverage.py [--rigs 40] [--seed 0] [--record 480] [--out F.jsonl]``.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

URAD = 1e-6


def draw_rig(rng: np.random.Generator) -> dict[str, Any]:
    """A rig's noise parameters (see the module docstring)."""
    from simhw.config import nominal_pickoff_lines

    axis = "X" if rng.random() < 0.5 else "Y"
    nea0 = {"X": 0.451, "Y": 0.506}[axis]
    pick0 = {"X": 6.2, "Y": 12.4}[axis]
    rms = pick0 * float(rng.uniform(0.5, 2.0))
    lines = [
        [round(f + float(rng.uniform(-1, 1)), 3), a * float(rng.uniform(0.5, 2.0))]
        for f, a in nominal_pickoff_lines(rms)
    ]
    var_lines = sum(a * a / 2 for _, a in lines)
    if var_lines > 0.95 * rms**2:  # the lines may not carry more than the rms
        k = math.sqrt(0.95 * rms**2 / var_lines)
        lines = [[f, a * k] for f, a in lines]
    knee = 1.0 if rng.random() < 0.5 else float(rng.uniform(0.0, 1.0))
    return {
        "axis": axis,
        "nea_urad": round(nea0 * float(rng.uniform(0.6, 1.6)), 4),
        "flicker_corner_hz": round(float(rng.uniform(1.5, 5.0)), 3),
        "flicker_knee": round(knee, 3),
        "flicker_slope": round(
            float(rng.uniform(0.8, 1.2)) if knee < 1.0 or rng.random() < 0.5 else 1.0, 3
        ),
        "common_noise_fraction": round(float(rng.uniform(0.0, 0.6)), 3),
        "nea_z": round(2.78 * float(rng.uniform(0.6, 1.6)), 3),
        "pickoff_noise_rms_urad": round(rms, 4),
        "pickoff_lines": [[f, round(a, 4)] for f, a in lines],
    }


def rig_config(d: dict[str, Any]):
    from simhw.config import from_dict

    a = d["axis"]
    ac = {
        k: d[k]
        for k in (
            "nea_urad",
            "flicker_corner_hz",
            "flicker_knee",
            "flicker_slope",
            "common_noise_fraction",
        )
    }
    return from_dict(
        {
            "autocollimator": {a: ac},
            "azimuth": {"nea_urad": d["nea_z"]},
            "gyro": {
                a: {
                    "pickoff_noise_rms_urad": d["pickoff_noise_rms_urad"],
                    "pickoff_lines": d["pickoff_lines"],
                }
            },
        }
    )


def truths(cfg, axis: str, rate_hz: float) -> dict[str, float]:
    """The simulator's values of every figure (see the module docstring)."""
    from drivers.rig_datasheet import AutocollimatorConstants
    from procedures.analysis.baseline import NEA_BAND_HZ, PICKOFF_BANDS_HZ, nea_truth
    from procedures.analysis.transfer import sensor_filter
    from simhw.simulator import Simulator, ac_white_psd

    sim = Simulator(cfg, rate_hz=rate_hz, mode=1, spin=0.0)
    ac = cfg.autocollimator[axis]
    consts = AutocollimatorConstants(
        ac.control_scale_mV_per_urad,
        ac.inst_scale_mV_per_urad,
        ac.control_filter_rad_per_s,
        ac.control_filter_zeta,
        ac.inst_filter1_rad_per_s,
        ac.inst_filter2_rad_per_s,
        ac.inst_filter2_zeta,
    )
    f = np.geomspace(*NEA_BAND_HZ, 6000)
    out: dict[str, float] = {}
    angle = sum(sim.sources.spectrum(f"nac_{axis}", f).values()) / URAD**2
    for k in ("ctl", "inst"):
        out[f"nea_urad.{k}"] = nea_truth(
            f, angle, np.abs(sensor_filter(f, consts, f"ac_{axis.lower()}_{k}")) ** 2
        )
    out["nea_urad.z"] = nea_truth(
        f, sum(sim.sources.spectrum("nac_Z", f).values()) / URAD**2, np.ones_like(f)
    )
    w = ac_white_psd(
        ac.nea_urad,
        ac.flicker_corner_hz,
        ac.control_filter_rad_per_s,
        ac.control_filter_zeta,
        knee=ac.flicker_knee,
        slope=ac.flicker_slope,
    )
    for k in ("ctl", "inst"):
        out[f"white_urad_per_rtHz.{k}"] = math.sqrt(w) / URAD
        out[f"flicker_corner_hz.{k}"] = ac.flicker_corner_hz
    for band, (lo, hi) in PICKOFF_BANDS_HZ.items():
        fb = np.linspace(lo, hi, 20001)
        white = (
            float(np.trapezoid(sum(sim.sources.spectrum(f"np_{axis}", fb).values()), fb)) / URAD**2
        )
        lines = (
            sum(a * a / 2 for fl, a in sim.sources.lines(f"np_{axis}") if lo <= fl <= hi) / URAD**2
        )
        out[f"pickoff_rms_urad.{band}"] = math.sqrt(white + lines)
    return out


def run_rig(i: int, seed: int, record_s: float, rate_hz: float = 1000.0) -> dict[str, Any]:
    from drivers.rig_datasheet import AutocollimatorConstants
    from procedures.analysis.baseline import array_blocks, baseline_figures
    from simhw.simulator import Simulator

    rng = np.random.default_rng([seed, i])
    d = draw_rig(rng)
    cfg = rig_config(d)
    a = d["axis"].lower()
    names = {"ctl": f"ac_{a}_ctl", "inst": f"ac_{a}_inst", "z": "ac_z", "gyro": f"gyro_{a}"}
    sim = Simulator(
        cfg, rate_hz=rate_hz, seed=int(rng.integers(2**31)), mode=3, channels=tuple(names.values())
    )
    sim.advance(int(rate_hz))
    sim.set_clamp(True)
    sim.advance(int(5 * rate_hz))
    b = sim.advance(int(record_s * rate_hz))
    x = np.column_stack([b[c] for c in names.values()])
    blocks = array_blocks(x, rate_hz, tuple(names.values()), 40.0, 8)
    ac = (
        AutocollimatorConstants(5.70, 5.63)
        if d["axis"] == "X"
        else AutocollimatorConstants(5.99, 5.92)
    )
    scales = {
        "ctl": ac.control_mV_per_urad * 1e-3,
        "inst": ac.inst_mV_per_urad * 1e-3,
        "z": 7.36e-3,
        "gyro": {"X": 6.03, "Y": 6.70}[d["axis"]] * 1e-3,
    }
    figs = baseline_figures(blocks, ac, names, scales)
    truth = truths(cfg, d["axis"], rate_hz)
    rec: dict[str, Any] = {"rig": d, "figures": {}}
    for key, e in figs.items():
        t = truth[key]
        rec["figures"][key] = {
            "value": e.value,
            "lo": e.lo,
            "hi": e.hi,
            "resolved": e.resolved,
            "truth": t,
            "covered": bool(e.lo <= t <= e.hi),
        }
    return rec


def table(recs: list[dict[str, Any]]) -> str:
    keys = sorted({k for r in recs for k in r["figures"]})
    lines = [
        f"{'figure':<34s} {'n':>4s} {'covered':>8s} {'med |err|':>10s} {'max |err|':>10s} {'unresolved':>10s}"
    ]
    for k in keys:
        items = [r["figures"][k] for r in recs if k in r["figures"]]
        n = len(items)
        cov = sum(i["covered"] for i in items)
        err = [
            abs(i["value"] / i["truth"] - 1)
            for i in items
            if math.isfinite(i["value"]) and i["truth"]
        ]
        unres = sum(not i["resolved"] for i in items)
        lines.append(
            f"{k:<34s} {n:>4d} {cov:>4d}/{n:<3d} {100 * statistics.median(err):>9.2f}% "
            f"{100 * max(err):>9.2f}% {unres:>6d}/{n:<3d}"
        )
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rigs", type=int, default=40)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--record", type=float, default=480.0)
    ap.add_argument("--out", type=Path)
    args = ap.parse_args()
    recs = []
    out = args.out.open("w") if args.out else None
    for i in range(args.rigs):
        r = run_rig(i, args.seed, args.record)
        recs.append(r)
        if out:
            out.write(json.dumps(r) + "\n")
            out.flush()
        print(
            f"rig {i}: "
            + ", ".join(
                f"{k} {'ok' if v['covered'] else 'MISS'}"
                for k, v in r["figures"].items()
                if not v["covered"]
            ),
            file=sys.stderr,
        )
    print(table(recs))


if __name__ == "__main__":
    main()
