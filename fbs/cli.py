"""The ``fbs`` command line (DESIGN.md section 7). Logs go to stderr; results to stdout."""

from __future__ import annotations

import argparse
import importlib.metadata
import logging
import sys
from contextlib import nullcontext

from drivers.errors import DriverError
from fbs import analyze, batch, demo, inspect, run, spectra
from fbs import gap as gap_cli
from fbs.signals import aborting_on_signals
from simhw import effects as effect_catalogue
from simhw.params import ConfigError, load_config

log = logging.getLogger("fbs")
#: DESIGN.md section 5 names 20 channels: a recording's disk check assumes all of them unless
#: --channels names fewer
SECTION_5_CHANNELS = 20
#: no ADC this software drives streams more sample sets per second (the sim's: 2 MS/s shared);
#: the ADC itself refuses, with its own limit, a rate it cannot keep up for the channels asked
MAX_RECORD_RATE_HZ = 2_000_000.0
#: what a command reports as ``fbs CMD: error: ...`` and exit 2 (``fbs batch`` records the same per file)
COMMAND_ERRORS = (ConfigError, ValueError, OSError, DriverError)


def _simulate(args: argparse.Namespace) -> int:
    from fbs.simulate import simulate_to_file

    cfg = load_config(args.sim_config)
    applied = []
    for spec in args.effect or []:
        effect, values, axis = effect_catalogue.parse_spec(spec)
        cfg = effect.inject(cfg, axis, **values)
        applied.append(spec)
    path = simulate_to_file(cfg, args.out, mode=args.mode, duration_s=args.duration, rate_hz=args.rate,
                            seed=args.seed, truth=args.truth, effects=applied, overwrite=args.force)
    print(f"wrote {path}: mode {args.mode}, {args.duration:g} s at {args.rate:g} Hz"
          + (f", effects {', '.join(applied)}" if applied else ""))
    return 0


def _record(args: argparse.Namespace) -> int:
    from daq.recorder import record
    from daq.runfile import check_request
    from drivers.rig import open_rig

    channels = [c for c in args.channels.split(",") if c] if args.channels else None
    # every argument and --out fail before the rig is told anything (the ADC refuses a rate
    # beyond its own aggregate limit; this bound is the most any ADC here delivers)
    check_request(args.out, duration_s=args.duration, rate_hz=args.rate, max_rate_hz=MAX_RECORD_RATE_HZ,
                  n_channels=len(channels) if channels else SECTION_5_CHANNELS)
    with open_rig(args.rig) as rig:
        rig.set_mode(args.mode)  # disallowed modes and interlocks are refused here, with the reason
        result = record(rig, args.out, duration_s=args.duration, rate_hz=args.rate, channels=channels)
    lost = f", {result.lost} samples lost in {len(result.gaps)} gap(s)" if result.gaps else ""
    print(f"wrote {result.path}: mode {args.mode}, {result.samples} samples at {result.rate_hz:g} Hz, "
          f"status {result.status}{lost}")
    return 0


def _console(args: argparse.Namespace) -> int:
    from console.app import run_console  # Textual is imported only for the console

    return run_console(args.rig, args.out)


def _version() -> str:
    try:
        return importlib.metadata.version("fbs-hil")
    except importlib.metadata.PackageNotFoundError:  # a checkout that was never installed
        return "unknown"


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="fbs", description="Fixed Base Simulator HIL: DAQ, procedures, simulation.")
    p.add_argument("-v", "--verbose", action="store_true", help="debug logging on stderr")
    p.add_argument("--version", action="version", version=f"fbs-hil {_version()}")
    sub = p.add_subparsers(dest="command", required=True)

    s = sub.add_parser("simulate", help="the plant offline, in virtual time, no drivers")
    s.add_argument("--mode", type=int, required=True, choices=range(1, 7), metavar="{1..6}")
    s.add_argument("--duration", type=float, required=True, help="seconds")
    s.add_argument("--rate", type=float, required=True, help="output sample rate, Hz")
    s.add_argument("--sim-config", help="TOML sim config")
    s.add_argument("--effect", action="append", metavar="NAME:k=v,..",
                   help="inject an effect (DESIGN.md section 8), e.g. pickup_line:freq_hz=200,amplitude_V=0.003")
    s.add_argument("--truth", action="store_true", help="also record the true platform angles")
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--out", required=True, help="output .h5 file (never replaced unless --force)")
    s.add_argument("--force", action="store_true",
                   help="replace an existing --out (never one a writer may still be filling)")
    s.set_defaults(func=_simulate)

    r = sub.add_parser("record", help="record the rig's ADC channels to an fbs-run file")
    r.add_argument("--rig", default="sim", help="rig URL (default: the simulated rig, 'sim')")
    r.add_argument("--mode", type=int, required=True, help="mode to record in (1-6; the rig checks interlocks)")
    r.add_argument("--duration", type=float, required=True, help="seconds")
    r.add_argument("--rate", type=float, required=True, help="sample rate per channel, Hz")
    r.add_argument("--channels", help="comma-separated channel names (default: all)")
    r.add_argument("--out", required=True, help="output .h5 file")
    r.set_defaults(func=_record)

    c = sub.add_parser("console", help="the operator console (Textual): meters, modes, set-points, recording, "
                                       "procedures, spectra")
    c.add_argument("--rig", default="sim?realtime=1",
                   help="rig URL (default: the simulated rig paced to the wall clock, 'sim?realtime=1')")
    c.add_argument("--out", default="out", help="directory for recordings, procedure runs and console.log "
                                                "(default: out)")
    c.set_defaults(func=_console)

    inspect.add_parser(sub)
    spectra.add_parser(sub)
    run.add_parser(sub)
    demo.add_parser(sub)
    analyze.add_parser(sub)
    gap_cli.add_parser(sub)
    batch.add_parser(sub)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.INFO, stream=sys.stderr,
                        format="%(levelname)s %(name)s: %(message)s")
    try:
        # the console owns its terminal and its signals (Textual); every other command aborts alike
        with nullcontext() if args.command == "console" else aborting_on_signals():
            return args.func(args)
    except COMMAND_ERRORS as exc:
        print(f"fbs {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"fbs {args.command}: interrupted", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
