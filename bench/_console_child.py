"""Child of ``bench/console_meters.py`` (a helper: ``run_all`` skips ``_*.py``).

``console``: the real console (``ConsoleApp``, real terminal driver: the parent gives it a
pseudo-terminal of 80x24) on the paced sim rig; once the rig is open it starts a recording
of 16 channels at 1 kHz, lets it run ``--warmup`` s, then counts meter-table paints and this
process's CPU time (``resource.getrusage``: every thread, the simulated rig's included) for
``--seconds``, stops the recording and quits. ``baseline``: the same rig and recording with
no console (``daq.recorder.record`` in this thread). Either prints one JSON line to ``--json``.
"""

from __future__ import annotations

import argparse
import json
import resource
import sys
import time
from pathlib import Path

CHANNELS16 = (
    "ac_x_ctl",
    "ac_y_ctl",
    "ac_x_inst",
    "ac_y_inst",
    "ac_z",
    "gyro_x",
    "gyro_y",
    "gyro_z",
    "gyro_xrd",
    "torq_x",
    "torq_y",
    "torq_z",
    "torq_xrd",
    "pa_x",
    "pa_y",
    "pa_z",
)
RATE_HZ = 1000.0


def cpu_s() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def console(args) -> dict:
    from console.app import ConsoleApp, RigNews
    from console.meters import MeterTable
    from console.state import RecordingEnded, RigReady

    out: dict = {}

    class BenchConsole(ConsoleApp):
        def on_rig_news(self, msg: RigNews) -> None:
            super().on_rig_news(msg)
            if isinstance(msg.item, RigReady):
                self.worker_.start_recording(Path(args.out) / "bench.h5", RATE_HZ, CHANNELS16)
                self.set_timer(args.warmup, self.mark0)
            elif isinstance(msg.item, RecordingEnded):
                out.update(status=msg.item.status, samples=msg.item.samples, gaps=msg.item.gaps)
                self.exit(0)

        def mark0(self) -> None:
            self._t0, self._c0 = time.monotonic(), cpu_s()
            self._p0 = self.query_one(MeterTable).paints
            self.set_timer(args.seconds, self.mark1)

        def mark1(self) -> None:
            wall = time.monotonic() - self._t0
            out.update(
                wall_s=wall,
                cpu_s=cpu_s() - self._c0,
                paints=self.query_one(MeterTable).paints - self._p0,
            )
            self.worker_.stop_recording()

    app = BenchConsole(args.rig, out_dir=args.out)
    app.run()
    return out


def baseline(args) -> dict:
    from daq.recorder import record
    from drivers.rig import open_rig

    with open_rig(args.rig) as rig:
        t0, c0 = time.monotonic(), cpu_s()
        res = record(
            rig,
            Path(args.out) / "baseline.h5",
            duration_s=args.warmup + args.seconds,
            rate_hz=RATE_HZ,
            channels=CHANNELS16,
        )
        # the whole recording is timed here: there is no UI to warm up, and the rig's start is done
        return {
            "wall_s": time.monotonic() - t0,
            "cpu_s": cpu_s() - c0,
            "samples": res.samples,
            "gaps": len(res.gaps),
            "status": res.status,
        }


def main() -> int:
    p = argparse.ArgumentParser()
    p.add_argument("what", choices=("console", "baseline"))
    p.add_argument("--rig", default="sim?realtime=1")
    p.add_argument("--out", required=True)
    p.add_argument("--warmup", type=float, default=5.0)
    p.add_argument("--seconds", type=float, default=20.0)
    p.add_argument("--json", required=True)
    args = p.parse_args()
    import logging

    # the terminal is the console's: the records go to a file (as ``run_console`` does)
    logging.basicConfig(
        filename=str(Path(args.out) / "console.log"),
        level=logging.INFO,
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
    )
    result = console(args) if args.what == "console" else baseline(args)
    Path(args.json).write_text(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
