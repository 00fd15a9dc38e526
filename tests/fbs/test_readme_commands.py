"""The README's command list is the command line (issue 40 item 6): every command the parser
knows is listed, and every option a listed line shows is one its parser accepts - so the
README cannot drift from ``fbs`` again (it left out ``fbs campaign``)."""

from __future__ import annotations

import argparse
import re
from pathlib import Path

from fbs.cli import COMMANDS, build_parser

README = Path(__file__).resolve().parents[2] / "README.md"


def _block() -> list[str]:
    """The README's "## Command line" block: the indented lines, continuations joined."""
    text = README.read_text()
    body = text.split("## Command line", 1)[1].split("\n## ", 1)[0]
    lines: list[str] = []
    for line in body.splitlines():
        if not line.startswith("    ") or not line.strip():
            continue
        if line.lstrip().startswith("fbs "):
            lines.append(line.strip())
        elif lines:
            lines[-1] += " " + line.strip()
    return lines


def _subparsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def test_every_command_is_in_the_readme_and_every_option_shown_is_real():
    lines = _block()
    listed = {m.group(1) for ln in lines for m in [re.match(r"fbs (\w+)", ln)] if m}
    assert set(COMMANDS) <= listed, f"not in the README: {sorted(set(COMMANDS) - listed)}"
    subs = _subparsers(build_parser())
    for ln in lines:
        cmd = ln.split()[1]
        if cmd not in subs:
            continue  # "fbs --version;  fbs -v COMMAND"
        parser = subs[cmd]
        options = {s for a in parser._actions for s in a.option_strings}
        for nested in _subparsers(parser).values():  # fbs analyze hysteresis|transfer
            options |= {s for a in nested._actions for s in a.option_strings}
        shown = set(re.findall(r"(?<![\w-])(--[a-z][a-z-]*)", ln))
        assert shown <= options, (
            f"README: {ln!r} shows {sorted(shown - options)}, which fbs {cmd} does not take"
        )
