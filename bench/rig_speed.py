"""Speed of the simulated rig through the drivers, procedure by procedure (issue 39).

Every procedure of ``fbs demo``'s campaign (``fbs.demo.campaign()``, its default parameters) runs
on the sim rig (``open_rig("sim?...")``: real bytes over a pty and CANopen frames on a virtual
bus) and is timed: rig seconds (the rig's clock across the run) per wall second, its x real
time. The baseline is measured in the same run: the offline simulator
(``simhw.simulator.Simulator``, no drivers) advancing the same channels at the same rate, in
1 s blocks, for the same rig time (at most ``BASELINE_CAP_S``), in the same process, the fastest
of ``BASELINE_REPEATS`` runs. Reported:
x real time (target >= 50) and the share of the offline speed the rig reaches (target >= 0.3).
Both are given for the whole run and for its steps alone (the rig's part: drivers, device
emulation and physics; the progress's phase changes to "analysing" where they end), with the
seconds the analysis and the report took after them.

The offline simulator for a procedure's channels is the reduced model (``simhw.reduction``: one
axis's four channels drop the other axes, the gyros and their noise). The sim rig cannot reduce:
its caging module reports each gyro's null from the pickoff (``simhw.rig_server``), so every
gyro and, through them, every axis is simulated whatever the ADC records. The last column is
therefore the steps' share of the offline speed of the whole rig at the same rate, the ceiling
the drivers and the device emulation are measured against (not a target).

Benchmarks report, they never fail: the exit code is 0 and a missed target prints
``TARGET MISSED``. Usage: ``python bench/rig_speed.py [--only excitation,hysteresis]`` (``--only``
runs just those, without the campaign's earlier procedures as their prior).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import tempfile
import time
from pathlib import Path

from fbs.cli import BLAS_THREADS

# the BLAS threads `fbs run` runs with, set before numpy loads
for _var, _value in BLAS_THREADS.items():
    os.environ.setdefault(_var, _value)

import h5py  # noqa: E402

TARGET_X_REALTIME = 50.0
TARGET_SHARE = 0.3
BASELINE_CAP_S = 300.0
BASELINE_REPEATS = 3


def offline_speed(channels: list[str] | None, rate_hz: float, rig_s: float, seed: int = 0) -> float:
    """Rig seconds per wall second of the offline simulator on ``channels`` (None: the whole
    rig) at ``rate_hz``: the fastest of ``BASELINE_REPEATS`` runs (one short run on a shared
    machine read anywhere from 325x to 550x for the same channels; the fastest is the speed
    the simulator has, and the share against it is not flattered by a slow moment)."""
    from simhw.simulator import Simulator

    sim = Simulator(None, rate_hz=rate_hz, seed=seed, mode=3, channels=channels)
    sim.advance(int(rate_hz))  # kernels compiled, caches warm
    seconds = min(rig_s, BASELINE_CAP_S)
    best = math.inf
    for _ in range(BASELINE_REPEATS):
        t0 = time.perf_counter()
        for _ in sim.run(seconds, block_s=1.0):
            pass
        best = min(best, time.perf_counter() - t0)
    return seconds / best


def main(argv: list[str] | None = None) -> int:
    from drivers.rig import open_rig
    from fbs.demo import campaign
    from procedures.calibrations import get
    from procedures.params import parse_params
    from procedures.progress import STEPS, Progress
    from procedures.runner import run_procedure

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument(
        "--only", default="", help="comma-separated procedure names (default: the whole campaign)"
    )
    a = ap.parse_args(argv)
    only = {s.strip() for s in a.only.split(",") if s.strip()}
    rows = []
    prior: dict[str, dict] = {}
    with tempfile.TemporaryDirectory() as d, open_rig("sim?seed=0&watchdog=5") as rig:
        for i, (name, axis, params) in enumerate(campaign()):
            if only and name not in only:
                continue  # not run at all: a procedure without its prior runs as ``fbs run`` does
            cls = get(name)
            proc = cls(parse_params(cls, list(params), axis), prior=prior)
            t_rig, t_wall = rig.now(), time.perf_counter()
            steps_end: list[float] = []

            def progress(p: Progress, steps_end: list[float] = steps_end) -> None:
                if p.phase != STEPS and not steps_end:
                    steps_end.append(time.perf_counter())

            s = run_procedure(proc, rig, Path(d) / f"{i}-{name}", progress=progress)
            wall = time.perf_counter() - t_wall
            steps_wall = (steps_end[0] if steps_end else time.perf_counter()) - t_wall
            rig_s = rig.now() - t_rig
            if s.verdict in ("pass", "fail"):
                prior[name] = dict(s.values) | ({"_file": str(s.file)} if s.file else {})
            label = name + (f" {axis}" if axis else "") + (" (gyro mode)" if params else "")
            if s.file is None:
                print(f"{label}: no file ({s.status})", file=sys.stderr)
                continue
            with h5py.File(s.file, "r") as f:
                chans = list(f["channels"])
                rate = float(f["channels"][chans[0]].attrs["sample_rate_hz"])
            base = offline_speed(chans, rate, rig_s)
            whole = offline_speed(None, rate, rig_s)
            rows.append(
                (
                    label,
                    rig_s,
                    wall,
                    rig_s / wall,
                    base,
                    rig_s / wall / base,
                    rig_s / steps_wall,
                    wall - steps_wall,
                    len(chans),
                    rate,
                    s.verdict,
                    whole,
                )
            )
            print(
                f"{label}: {rig_s:.0f} rig s in {wall:.1f} s, {rig_s / wall:.1f}x real time; offline "
                f"{base:.0f}x ({len(chans)} channels at {rate:g} Hz)",
                file=sys.stderr,
                flush=True,
            )
    print(
        f"{'procedure':<28} {'rig s':>7} {'wall s':>7} {'x real':>7} {'offline x':>9} {'share':>6}"
        f" {'steps x':>8} {'share':>6} {'analysis s':>10} {'whole rig x':>11} {'share':>6}"
        "  channels, rate"
    )
    for label, rig_s, wall, x, base, share, xs, after, nch, rate, verdict, whole in rows:
        miss = [f"x real {x:.1f} < {TARGET_X_REALTIME:g}"] if x < TARGET_X_REALTIME else []
        miss += [f"share {share:.2f} < {TARGET_SHARE:g}"] if share < TARGET_SHARE else []
        print(
            f"{label:<28} {rig_s:7.0f} {wall:7.1f} {x:7.1f} {base:9.0f} {share:6.2f} {xs:8.1f}"
            f" {xs / base:6.2f} {after:10.1f} {whole:11.0f} {xs / whole:6.2f}"
            f"  {nch} at {rate:g} Hz ({verdict})"
            + (f"  TARGET MISSED: {'; '.join(miss)}" if miss else "")
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
