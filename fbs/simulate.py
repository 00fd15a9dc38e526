"""``fbs simulate``: the plant offline, in virtual time, no drivers (DESIGN.md section 7).

``--json`` prints one object instead of the summary line: ``file``, ``mode``, ``rate_hz``,
``n_samples``, ``duration_s``, ``status``, ``channels`` {name: units}, ``seed``, ``truth``,
``effects``. The simulator (numba) is imported only when the command runs: ``fbs --help``
stays fast.
"""

from __future__ import annotations

import argparse
import logging
from pathlib import Path
from typing import TYPE_CHECKING, Any

from fbs import jsonout

if TYPE_CHECKING:
    from simhw.config import SimConfig

log = logging.getLogger(__name__)


#: the plant's ZOH loop at this output rate already runs far slower than real time
MAX_RATE_HZ = 100_000.0


def simulate_to_file(
    cfg: SimConfig,
    out: str | Path,
    *,
    mode: int,
    duration_s: float,
    rate_hz: float,
    seed: int = 0,
    truth: bool = False,
    effects: list[str] | None = None,
    block_s: float = 10.0,
    overwrite: bool = False,
    config_path: str | None = None,
) -> Path:
    """Simulate ``duration_s`` seconds and write an "fbs-run" file; returns its path. The request
    is checked first (``daq.runfile.check_request``): an existing ``out`` is replaced only with
    ``overwrite``. ``config_path``: the sim config ``cfg`` was read from (the file's
    provenance)."""
    from daq import provenance
    from daq.runfile import RunWriter, check_request
    from simhw.config import config_stamp, to_dict
    from simhw.plant import CHANNELS, TRUTH_CHANNELS
    from simhw.simulator import Simulator

    check_request(
        out,
        duration_s=duration_s,
        rate_hz=rate_hz,
        max_rate_hz=MAX_RATE_HZ,
        n_channels=len(CHANNELS) + (len(TRUTH_CHANNELS) if truth else 0),
        overwrite=overwrite,
    )
    sim = Simulator(cfg, rate_hz=rate_hz, seed=seed, mode=mode, truth=truth)
    units = {c: "V" for c in CHANNELS} | ({t: "rad" for t in TRUTH_CHANNELS} if truth else {})
    meta = {
        "configuration": to_dict(cfg),
        "seed": seed,
        "effects": effects or [],
        "calibration": {},
        "source": "fbs simulate (virtual time, no drivers)",
        "provenance": provenance.offline("sim-offline", config_stamp(config_path)),
    }
    with RunWriter(
        out,
        rig="sim-offline",
        mode=mode,
        rate_hz=rate_hz,
        channels=units,
        meta=meta,
        overwrite=overwrite,
    ) as w:
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
                    w.event(
                        block.t0 + first / rate_hz,
                        "overrange",
                        f"{c}: {int(over.sum())} samples beyond range",
                    )
    return Path(out)


def json_result(args: argparse.Namespace) -> dict[str, Any]:
    """Simulate as asked; the object ``--json`` prints."""
    from daq.reader import RunFile
    from simhw import effects as effect_catalogue
    from simhw.config import load_config

    cfg = load_config(args.sim_config)
    applied = []
    for spec in args.effect or []:
        effect, values, axis = effect_catalogue.parse_spec(spec)
        cfg = effect.inject(cfg, axis, **values)
        applied.append(spec)
    path = simulate_to_file(
        cfg,
        args.out,
        mode=args.mode,
        duration_s=args.duration,
        rate_hz=args.rate,
        seed=args.seed,
        truth=args.truth,
        effects=applied,
        overwrite=args.force,
        config_path=args.sim_config,
    )
    with RunFile(path) as run:
        return {
            "file": str(path),
            "mode": args.mode,
            "rate_hz": run.rate_hz,
            "n_samples": run.n_samples,
            "duration_s": run.duration_s,
            "status": run.status,
            "channels": dict(run.units),
            "seed": args.seed,
            "truth": bool(args.truth),
            "effects": applied,
        }


def _simulate(args: argparse.Namespace) -> int:
    result = json_result(args)
    if args.json:
        print(jsonout.dumps(result))
        return 0
    print(
        f"wrote {result['file']}: mode {args.mode}, {args.duration:g} s at {args.rate:g} Hz"
        + (f", effects {', '.join(result['effects'])}" if result["effects"] else "")
    )
    return 0


def add_parser(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("simulate", help="the plant offline, in virtual time, no drivers")
    s.add_argument("--mode", type=int, required=True, choices=range(1, 7), metavar="{1..6}")
    s.add_argument("--duration", type=float, required=True, help="seconds")
    s.add_argument("--rate", type=float, required=True, help="output sample rate, Hz")
    s.add_argument("--sim-config", help="TOML sim config")
    s.add_argument(
        "--effect",
        action="append",
        metavar="NAME:k=v,..",
        help="inject an effect of the model-gap catalogue (the names `fbs gap` reports), "
        "e.g. pickup_line:freq_hz=200,amplitude_V=0.003",
    )
    s.add_argument("--truth", action="store_true", help="also record the true platform angles")
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--out", required=True, help="output .h5 file (never replaced unless --force)")
    s.add_argument(
        "--force",
        action="store_true",
        help="replace an existing --out (never one a writer may still be filling)",
    )
    s.add_argument(
        "--json",
        action="store_true",
        help="one JSON object on stdout: file, mode, rate_hz, n_samples, "
        "duration_s, status, channels with units, seed, truth, effects",
    )
    s.set_defaults(func=_simulate, json_result=json_result)
