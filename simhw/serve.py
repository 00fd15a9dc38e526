"""Serve the simulated rig to hosts in other processes: ``python -m simhw.serve``.

The sim rig of ``open_rig("sim")`` runs its devices in the host's own process. Served, the same
devices run here, paced to the wall clock as hardware is: the ADC on a pseudo-terminal, the
CANopen nodes on a bus that crosses processes (python-can ``udp_multicast``). A host reaches
it as it would a real rig, ``serial:///dev/pts/N?can=udp_multicast:GROUP``: the rig claim, the
connect sequence and every driver are the real ones. What a lab meets only with two machines
(a second host on the rig, docs/protocol.md 2.8) is then testable on one.

Prints ``adc=PATH can=udp_multicast:GROUP`` on stdout once the devices run, and serves until
stdin closes (or SIGTERM/SIGINT).

Usage: ``python -m simhw.serve --can GROUP [--seed N] [--config F.toml] [--warm]``
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading

from simhw.config import load_config
from simhw.rig_server import SimRigServer


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m simhw.serve", description=__doc__.split("\n")[0])
    ap.add_argument("--can", required=True, help="udp_multicast group address (e.g. 239.1.2.3)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--config", default=None, help="sim config (TOML)")
    ap.add_argument("--warm", action="store_true", help="start in mode 3, spun up and caged")
    a = ap.parse_args(argv)
    server = SimRigServer(
        load_config(a.config),
        seed=a.seed,
        realtime=True,
        warm=a.warm,
        can_channel=a.can,
        can_interface="udp_multicast",
    )
    done = threading.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: done.set())

    def until_stdin_closes() -> None:
        sys.stdin.read()
        done.set()

    threading.Thread(target=until_stdin_closes, name="stdin-eof", daemon=True).start()
    print(f"adc={server.adc_port} can=udp_multicast:{a.can}", flush=True)
    try:
        done.wait()
    finally:
        server.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
