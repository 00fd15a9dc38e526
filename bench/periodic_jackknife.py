"""How well the excitation's jackknife measures its own errors: records of one rig that differ
only in the rig's noise (issue 38, acceptance A: why the network corners over-cover).

One rig (``coverage_all.draw_rig(--rig)``) is recorded ``--records`` times by ``fbs run
excitation`` in Mode ``--mode``, each with another ``sim?seed=``; nothing else changes. Each
record is analysed as the procedure analyses it (``transfer.periodic_blocks``,
``network_in_loop``, ``fit_network``) and compared with the others and with the rig's truth:

* per bin of the network's in-loop response (1-30 Hz): the jackknife's standard error of ln|H|
  over the spread of ln|H| between the records (1 if the jackknife is right);
* per corner w1..w4: the jackknife's standard error over the rms error against the config;
* the correlation of neighbouring periods' errors at the lines, each period's own ratio against
  the record's (-0.5 where a period's error is the difference of the loop's states at its two
  ends, the leakage of its noise-driven transient: such errors telescope in the record's mean,
  which the jackknife, taking its blocks as independent, does not see);
* the blocks' correlation the network fit reads and allows for (``serial_variance_factor``),
  and the corners' standard errors with it, against their rms error.

Benchmarks report, they never fail. Usage: ``python bench/periodic_jackknife.py [--rig 0]
[--records 8] [--mode 3] [--jobs 1]`` (~20 s of a core per record).
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
from concurrent.futures import ThreadPoolExecutor  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from coverage_all import draw_rig  # noqa: E402
from coverage_pool import toml_of  # noqa: E402

CORNERS = ("w1_rad_per_s", "w2_rad_per_s", "w3_rad_per_s", "w4_rad_per_s")


def record(cfg_path: Path, seed: int, mode: int, out: Path) -> dict:
    """One excitation run on the rig of ``cfg_path`` with rig seed ``seed``; its summary."""
    cmd = [sys.executable, "-m", "fbs", "run", "excitation", "--axis", "X"]
    cmd += ["--rig", f"sim?seed={seed}&config={cfg_path}", "--param", f"mode={mode}"]
    cmd += ["--out", str(out)]
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode not in (0, 1):
        last = (done.stderr.strip().splitlines() or ["no message"])[-1]
        raise RuntimeError(f"{' '.join(cmd)}: exit {done.returncode}: {last}")
    return json.loads((out / "excitation.json").read_text())


def analyse(summary: dict, mode: int, divider: float) -> dict:
    """The record's in-loop network response, its fit and its periods' errors."""
    from procedures.analysis import transfer as T

    span = summary["spans"]["excite"]
    where = [(span["file"], span["start"], span["stop"])]
    chans = ["cmd_x", "pa_x", "ac_x_ctl" if mode == 3 else "gyro_x"]
    blocks = T.periodic_blocks(where, chans, summary["params"]["period_s"])
    resp = T.network_in_loop(blocks, chans[2], "pa_x", "cmd_x", divider)
    lo = max(summary["params"]["roots_lo_hz"], blocks.lowest_fit_hz)
    fit = T.fit_network(resp, lo, summary["params"]["roots_hi_hz"])
    ok = T.usable(resp, lo, summary["params"]["roots_hi_hz"])
    factor, _ = T.serial_variance_factor(np.log(resp.H_blocks[:, ok] / resp.H[ok]))
    x = np.log([fit.params[k] for k in CORNERS])
    xb = np.log([[r[k] for k in CORNERS] for r in fit.replicates])
    # each period alone: its error at the lines against the record's ratio
    periods = T.periodic_blocks(
        where, chans, summary["params"]["period_s"], int(blocks.weights.sum())
    )
    S = periods.S
    num, den = S[:, :, 0, 1] - divider * S[:, :, 0, 0], S[:, :, 0, 2]
    band = (periods.f >= 1.0) & (periods.f <= 30.0)
    e = (num - (num.mean(0) / den.mean(0)) * den)[:, band] / np.abs(den.mean(0)[band])
    lag1 = np.sum((e[1:] * np.conj(e[:-1])).real, 0) / np.sum(np.abs(e) ** 2, 0)
    keep = (resp.f >= 1.0) & (resp.f <= 30.0)
    return {
        "f": resp.f[keep],
        "log_h": np.log(np.abs(resp.H[keep])),
        "log_se": resp.log_se[keep],
        "x": x,
        "se": T.jackknife_se(xb),
        "factor": factor,
        "rho": fit.block_correlation,
        "lag1": float(np.median(lag1)),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rig", type=int, default=0, help="coverage_all's rig seed")
    ap.add_argument("--records", type=int, default=8)
    ap.add_argument("--mode", type=int, default=3, choices=(3, 4))
    ap.add_argument("--jobs", type=int, default=1)
    a = ap.parse_args(argv)
    from simhw.config import load_config

    cfg = draw_rig(a.rig)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "rig.toml"
        path.write_text(toml_of(cfg))
        divider = load_config(path).platform["X"].command_divider
        seeds = range(100, 100 + a.records)
        with ThreadPoolExecutor(a.jobs) as pool:
            runs = list(pool.map(lambda s: record(path, s, a.mode, Path(tmp) / f"r{s}"), seeds))
        recs = [analyse(r, a.mode, divider) for r in runs]
    truth = np.log([cfg["compensation"][k] for k in CORNERS])
    log_h = np.array([r["log_h"] for r in recs])
    log_se = np.sqrt(np.mean(np.array([r["log_se"] for r in recs]) ** 2, axis=0))
    ratio = log_se / log_h.std(axis=0, ddof=1)
    print(f"rig {a.rig}, Mode {a.mode}, {len(recs)} records of the same rig, noise seeds differ")
    f = recs[0]["f"]
    for lo, hi in ((1.0, 3.0), (3.0, 10.0), (10.0, 30.0)):
        s = (f >= lo) & (f < hi)
        print(
            f"  ln|H| {lo:g}-{hi:g} Hz: jackknife SE / spread between records, median "
            f"{float(np.median(ratio[s])):.2f}"
        )
    x = np.array([r["x"] for r in recs])
    se = np.sqrt(np.mean(np.array([r["se"] for r in recs]) ** 2, axis=0))
    rms = np.sqrt(np.mean((x - truth) ** 2, axis=0))
    factor = float(np.mean([r["factor"] for r in recs]))
    print(
        f"  the blocks' correlation the fit allows for (serial_variance_factor): median "
        f"{float(np.median([r['rho'] for r in recs])):+.2f}, variance factor {factor:.3f} "
        "on average"
    )
    for k, name in enumerate(CORNERS):
        print(
            f"  {name[:2]}: rms error {rms[k]:.5f} (ln); jackknife SE {se[k]:.5f}, ratio "
            f"{se[k] / rms[k]:.2f}; allowing for the correlation "
            f"{se[k] * np.sqrt(factor):.5f}, ratio {se[k] * np.sqrt(factor) / rms[k]:.2f}"
        )
    lag = [r["lag1"] for r in recs]
    print(
        f"  neighbouring periods' errors at the lines, 1-30 Hz: correlation median "
        f"{float(np.median(lag)):+.2f} (0 if independent, -0.5 if they telescope)"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
