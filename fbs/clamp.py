"""``fbs clamp on|off [--rig URL] [--json]``: engage or release the platform clamp by hand
(the open-loop state of Ch. V B; docs/protocol.md 2.5a).

The ``baseline`` procedure clamps and releases by itself; this is for the operator who finds
a rig left clamped (a procedure that needs the loops refuses to start on it, naming this
command). The relay node's interlocks hold: clamping only in modes 1-3 with the command inputs
at zero, releasing with the command inputs at zero; a refusal says what to do (exit code 2).
"""

from __future__ import annotations

import argparse

from fbs import jsonout


def _clamp(args: argparse.Namespace) -> int:
    from drivers.rig import open_rig

    with open_rig(args.rig) as rig:
        if args.state == "on":
            rig.clamp()
        else:
            rig.unclamp()
        st = rig.relays.status()
    if args.json:
        print(jsonout.dumps({"clamped": st.clamped, "mode": st.mode}))
    else:
        print(
            f"platform {'clamped (loops open)' if st.clamped else 'released (loops closed)'}; mode {st.mode}"
        )
    return 0


def add_parser(sub: argparse._SubParsersAction) -> None:
    c = sub.add_parser(
        "clamp", help="clamp the platform to the table (loops open, Ch. V B) or release it"
    )
    c.add_argument("state", choices=("on", "off"), help="on: clamp; off: release")
    c.add_argument("--rig", default="sim", help="rig URL (default: the simulated rig, 'sim')")
    c.add_argument("--json", action="store_true", help="print one JSON object: clamped, mode")
    c.set_defaults(func=_clamp)
