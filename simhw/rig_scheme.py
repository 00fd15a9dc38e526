"""The ``sim`` rig URL scheme: the real drivers served by the simulated devices.

``open_rig("sim?...")`` finds ``open_sim_rig`` through the ``fbs.rig_schemes`` entry point
(``pyproject.toml``), so ``drivers`` never imports ``simhw``. The rig it returns is the same
``drivers.rig.Rig`` a serial rig is - ADC on a pseudo-terminal, nodes on a python-can virtual
bus - with ``emulator`` set to the server, for fault injection in tests::

    sim                          virtual time, cold (mode 1, wheels stopped)
    sim?warm=1&seed=3            started in mode 3, caged, as after hours of running
    sim?realtime=1               paced to the wall clock
    sim?config=F.toml&table=manual&speed=1&watchdog=1   heartbeat/reply deadline 1 s (default 5 s)
    sim?can=virtual:NAME&external=torquer
                                 on virtual channel NAME; the torquer is a CANopen node the
                                 caller runs there (docs/protocol.md section 2)
"""

from __future__ import annotations

from drivers import rig_nodes as rn
from drivers.rig import Rig, assemble, check_keys, flag
from drivers.rig_datasheet import RigCalibration
from drivers.runclock import RunningClock
from drivers.table import Operator, TablePosition, terminal_operator
from simhw.can_nodes import InlineVirtualBus
from simhw.config import config_stamp, load_config
from simhw.datasheet import rig_calibration
from simhw.rig_server import SimRigServer
from simhw.simulator import check_seed

#: the simulated rig's default heartbeat and reply deadline (s, on a clock that leaves out the
#: host's pauses: ``drivers.runclock``)
SIM_WATCHDOG_S = 5.0
SIM_KEYS = {"realtime", "seed", "config", "warm", "table", "speed", "watchdog", "can", "external"}


def sim_can(url: str, params: dict[str, str]) -> tuple[str | None, list[str]]:
    """The sim's CAN options: ``can=virtual:NAME`` (the channel; virtual only: the sim's nodes
    run in this process) and ``external=a,b`` (nodes the caller runs on it itself)."""
    channel = None
    if "can" in params:
        iface, _, channel = params["can"].partition(":")
        if iface != "virtual" or not channel:
            raise ValueError(
                f"rig URL {url!r}: can={params['can']!r}: the sim's bus is python-can's "
                f"virtual one, give can=virtual:NAME"
            )
    external = [n for n in params.get("external", "").split(",") if n]
    nodes = rn.node_ids()
    bad = [n for n in external if n not in nodes]
    if bad:
        raise ValueError(
            f"rig URL {url!r}: external={params['external']!r}: unknown node(s) {', '.join(bad)} "
            f"(nodes: {', '.join(nodes)})"
        )
    return channel, external


def open_sim_rig(
    url: str, params: dict[str, str], operator: Operator | None, calibration: RigCalibration | None
) -> Rig:
    """Start the simulated rig's devices and connect the drivers to them."""
    check_keys(url, params, SIM_KEYS)
    table = params.get("table", "can")
    if table not in ("can", "manual"):
        raise ValueError(f"rig URL {url!r}: table={table!r} must be 'can' or 'manual'")
    try:
        seed = int(params.get("seed", "0"))
    except ValueError:
        seed = -1
    check_seed(seed, f"rig URL {url!r}: seed={params.get('seed', '0')!r}")
    try:
        speed = float(params.get("speed", "1"))
        # a wall-clock deadline on a rig whose time is virtual measures the host's load, not the
        # rig: the sim's heartbeat watchdogs and CAN reply deadline default to 5 s (a real rig's
        # nodes use 1 s), on a clock without the host's pauses; tests of the watchdog itself
        # give watchdog= explicitly
        watchdog = float(params.get("watchdog", str(SIM_WATCHDOG_S)))
    except ValueError as exc:
        raise ValueError(f"rig URL {url!r}: {exc}") from None
    channel, external = sim_can(url, params)
    cfg = load_config(params.get("config"))
    stamp = config_stamp(params.get("config"))  # read after the parse: a regular file
    if calibration is None:
        calibration = rig_calibration(cfg)  # the data sheet the simulated rig ships with
    # the devices run in this process: their deadlines, and the drivers', leave out the time the
    # process could not run (a busy host), so they measure the rig (``drivers.runclock``)
    running = RunningClock()
    try:
        server = SimRigServer(
            cfg,
            seed=seed,
            realtime=flag("realtime", params.get("realtime", "0")),
            speed=speed,
            warm=flag("warm", params.get("warm", "0")),
            watchdog_s=watchdog,
            monotonic=running,
            can_channel=channel,
            external_nodes=external,
        )
    except BaseException:
        running.close()
        raise
    try:
        bus = InlineVirtualBus(channel=server.can_channel, receive_own_messages=False)
        tab: tuple
        if table == "manual":
            t = server.sim.cfg.table
            tab = (
                "manual",
                operator or terminal_operator,
                TablePosition(t.tilt_deg, t.spindle_deg % 360.0),
            )
        else:
            tab = ("can",)
        return assemble(
            url,
            server.adc_port,
            bus,
            server.can_channel,
            server.clock,
            tab,
            calibration,
            node_timeout_s=watchdog,
            reply_timeout_s=max(0.5, watchdog),
            closers=[server.stop, running.close],
            emulator=server,
            monotonic=running,
            simulated=True,
            sim_config=stamp,
        )
    except BaseException:
        server.stop()
        running.close()
        raise
