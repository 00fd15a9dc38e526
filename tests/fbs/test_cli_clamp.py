"""``fbs clamp on|off``: the platform clamp by hand, through the relay node's interlocks."""

from __future__ import annotations

import json

from fbs.cli import main


def test_clamp_on_and_off_print_the_state(capsys):
    assert main(["clamp", "on", "--json"]) == 0
    assert json.loads(capsys.readouterr().out.strip().splitlines()[-1]) == {
        "clamped": True,
        "mode": 1,
    }
    assert main(["clamp", "off"]) == 0
    assert "released" in capsys.readouterr().out
