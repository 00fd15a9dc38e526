"""Issue 36 B: every ``--param`` of every procedure and every option of every command, given
hostile values (NaN, infinities, zero, negatives, a denormal, 1e300, unicode, URL metacharacters,
a newline, the empty string), ends in a clean error that names what was refused - or in the
same outcome as a sane value, never in a traceback, a hang or a rig opened for a value that
is then refused.

The options are read from the parser itself (``fbs.cli.build_parser``), so a new option is
driven without editing this file; a new command fails ``test_every_command_has_a_base_here``
until it has a base command line below. Each base is a command that gets as far as it can
without long work and then fails on something unrelated and late (a sim config that does not
exist, a scheduler where nothing listens): a hostile value that changes the outcome must then
have been refused, and its refusal must name the option or the value.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import re
from pathlib import Path

import pytest

from fbs.cli import build_parser, main
from fbs.usage import one_line
from procedures.calibrations import catalogue
from procedures.params import parse_params

#: what a slip of the hand, a script's bug or an attacker types into a value
HOSTILE = ["nan", "inf", "-inf", "0", "-1", "1e-320", "1e300", "ünï", "a&b?c#d", "x\ny", ""]
#: the same, as ``--param k=v`` values (JSON where it parses, else text)
HOSTILE_PARAMS = [
    "NaN",
    "Infinity",
    "-Infinity",
    "0",
    "-1",
    "1e-320",
    "1e300",
    "1.5",
    '"ünï"',
    '"a&b?c#d"',
    "x\ny",
    "[]",
    "{}",
    "true",
    "null",
    '["X", "X"]',
    '{"Q": 1}',
]

NO_RIG = "sim?config=/nonexistent/fbs-hostile.toml"  # fails as the rig opens, after every check
NO_SCHEDULER = "tcp://127.0.0.1:1"  # nothing listens: fails as the work starts

#: each command's base command line ({rec}: a small mode-3 recording, {tmp}: a fresh folder)
BASES: dict[str, list[str]] = {
    "simulate": [
        "--mode",
        "3",
        "--duration",
        "1",
        "--rate",
        "100",
        "--seed",
        "1",
        "--out",
        "{tmp}/s.h5",
    ],
    "record": [
        "--rig",
        NO_RIG,
        "--mode",
        "3",
        "--duration",
        "1",
        "--rate",
        "100",
        "--channels",
        "ac_x_ctl",
        "--out",
        "{tmp}/r.h5",
    ],
    "clamp": ["on", "--rig", NO_RIG],
    "inspect": ["{rec}", "--max-events", "3"],
    "recover": ["{tmp}/missing.h5"],
    "spectra": ["{rec}", "--channels", "ac_x_ctl", "--seg-s", "0.5", "--out", "{tmp}/sp"],
    "run": [
        "stopwatch",
        "--rig",
        NO_RIG,
        "--axis",
        "X",
        "--out",
        "{tmp}/o",
        "--param",
        "repetitions=1",
    ],
    "demo": ["--out", "{tmp}/d", "--sim-config", "/nonexistent/fbs-hostile.toml", "--seed", "1"],
    "analyze hysteresis": [
        "{rec}",
        "--axis",
        "X",
        "--settle-cycles",
        "1",
        "--angle-lag-ms",
        "1",
        "--out",
        "{tmp}/h",
    ],
    "analyze transfer": [
        "{rec}",
        "--from",
        "ac_x_ctl",
        "--to",
        "pa_x",
        "--fit",
        "none",
        "--seg-s",
        "0.5",
        "--blocks",
        "3",
        "--start",
        "0",
        "--stop",
        "2",
        "--lo-hz",
        "1",
        "--hi-hz",
        "20",
        "--out",
        "{tmp}/t",
    ],
    "gap": [
        "{rec}",
        "--axis",
        "X",
        "--seed",
        "1",
        "--report",
        "{tmp}/g",
        "--sim-config",
        "/nonexistent/fbs-hostile.toml",
    ],
    "batch": [
        "inspect",
        "{rec}",
        "--out",
        "{tmp}/b.jsonl",
        "--scheduler",
        NO_SCHEDULER,
        "--jobs",
        "1",
        "--args",
        "--max-events 1",
    ],
    "campaign": [
        "gap",
        "--effect",
        "pickup_line",
        "--grid",
        "amplitude_V=0.001:0.01:2",
        "--seeds",
        "1",
        "--duration",
        "2",
        "--out",
        "{tmp}/c",
        "--scheduler",
        NO_SCHEDULER,
        "--jobs",
        "1",
    ],
}
#: interactive: a full-screen app, driven by its own pilot tests (tests/console)
NOT_DRIVEN = {"console"}


def _commands() -> dict[str, argparse.ArgumentParser]:
    found: dict[str, argparse.ArgumentParser] = {}

    def walk(parser: argparse.ArgumentParser, prefix: str) -> None:
        subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
        if prefix and not subs:
            found[prefix] = parser
        for a in subs:
            for name, sub in a.choices.items():
                walk(sub, f"{prefix} {name}".strip())

    walk(build_parser(), "")
    return found


def _options(parser: argparse.ArgumentParser) -> list[argparse.Action]:
    return [a for a in parser._actions if a.nargs != 0 and not isinstance(a, argparse._HelpAction)]


def _substitute(
    base: list[str], parser: argparse.ArgumentParser, action: argparse.Action, value: str
) -> list[str]:
    """``base`` with ``action``'s value replaced by ``value`` (added when the base lacks it); a
    positional is the base's n-th leading word."""
    argv = list(base)
    if action.option_strings:
        flag = action.option_strings[-1]
        if flag in argv:
            argv[argv.index(flag) + 1] = value
        else:
            argv += [flag, value]
        return argv
    argv[[a for a in _options(parser) if not a.option_strings].index(action)] = value
    return argv


CASES = [
    (name, parser, action, value)
    for name, parser in _commands().items()
    if name not in NOT_DRIVEN
    for action in _options(parser)
    for value in HOSTILE
]


@pytest.fixture(scope="module")
def rec(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("rec") / "r.h5"
    assert (
        main(["simulate", "--mode", "3", "--duration", "2", "--rate", "100", "--out", str(path)])
        == 0
    )
    return path


def _run(capsys, argv: list[str]) -> tuple[int, str]:
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse's own exit (usage errors, --help)
        code = int(exc.code or 0)
    return code, capsys.readouterr().err


def _verdict(err: str) -> str:
    """The line that says how a command ended: its last ``error:`` line, else ""."""
    lines = [ln for ln in err.splitlines() if ": error: " in ln or "internal error" in ln]
    return lines[-1] if lines else ""


def _fill(words: list[str], rec: Path, tmp: Path) -> list[str]:
    return [w.replace("{rec}", str(rec)).replace("{tmp}", str(tmp)) for w in words]


def test_every_command_has_a_base_here():
    assert set(_commands()) - NOT_DRIVEN == set(BASES)


_BASE_OUTCOME: dict[str, tuple[int, str]] = {}


@pytest.mark.parametrize(
    "command, parser, action, value",
    CASES,
    ids=[
        f"{c}-{a.option_strings[-1] if a.option_strings else a.dest}-{v!r}" for c, _, a, v in CASES
    ],
)
def test_a_hostile_option_value_is_refused_by_name_or_changes_nothing(
    capsys, rec, tmp_path, monkeypatch, command, parser, action, value
):
    monkeypatch.chdir(tmp_path)  # a hostile relative path lands here, not in the checkout
    words = command.split()
    if command not in _BASE_OUTCOME:
        base_dir = tmp_path / "base"
        base_dir.mkdir()
        _BASE_OUTCOME[command] = _run(capsys, [*words, *_fill(BASES[command], rec, base_dir)])
    base_code, base_err = _BASE_OUTCOME[command]
    argv = [*words, *_fill(_substitute(BASES[command], parser, action, value), rec, tmp_path)]
    code, err = _run(capsys, argv)
    assert code in (0, 1, 2, 64), (argv, code, err)
    assert "Traceback" not in err and "internal error" not in err, (argv, err)
    said = _verdict(err).replace(str(tmp_path), "{tmp}")
    same = code == base_code and said == _verdict(base_err).replace(str(tmp_path / "base"), "{tmp}")
    if code in (2, 64) and not same:
        # refused: the refusal names the option (its flag or its name) or the value itself
        names = [
            *action.option_strings,
            action.dest,
            action.dest.replace("_", "-"),
            action.metavar or "",
        ]
        shown = {value, repr(value), value.strip(), one_line(value)} - {""}
        assert said, (argv, err)
        assert (
            any(n and n in said for n in names) or any(s in said for s in shown) or value == ""
        ), (argv, said)
        # and it came before the rig: a refusal after the rig opened is what this guards against
        assert "safe state reached" not in err, (argv, err)


# ---------------------------------------------------------------------------- --param
PARAM_CASES = [
    (name, f.name, v)
    for name, proc in sorted(catalogue().items())
    for f in dataclasses.fields(proc.Params)
    for v in HOSTILE_PARAMS
]


def _shown(raw: str) -> list[str]:
    """How a refusal may show the value ``raw`` was parsed to."""
    try:
        v = json.loads(raw)
    except ValueError:
        return [raw, repr(raw)]
    out = [raw, repr(v), str(v)]
    if isinstance(v, float) and not math.isfinite(v):
        out += ["nan", "inf", "-inf"]
    return out


@pytest.mark.parametrize(
    "procedure, name, raw", PARAM_CASES, ids=[f"{p}-{n}-{r!r}" for p, n, r in PARAM_CASES]
)
def test_a_hostile_param_is_refused_naming_it_and_its_limit_or_is_a_plan(procedure, name, raw):
    proc_cls = catalogue()[procedure]
    try:
        params = parse_params(proc_cls, [f"{name}={raw}"], None)
    except ValueError as exc:
        text = str(exc)
        assert re.search(rf"\b{re.escape(name)}\b", text), text
        # ... and the limit it broke
        assert any(
            w in text for w in ("must", "use ", "needs", "fewer than", "is beyond", ">=", "<=")
        ), text
        assert "Traceback" not in text
        return
    # accepted: within every declared limit, and the procedure makes its plan with it
    proc = proc_cls(params)
    assert proc.plan(), (procedure, name, raw)


@pytest.mark.parametrize("raw", ["NaN", "1e300", '"a&b?c#d"', "-1"])
def test_a_refused_param_stops_fbs_run_before_the_rig_opens(capsys, tmp_path, raw):
    code, err = _run(
        capsys, ["run", "stopwatch", "--out", str(tmp_path / "o"), "--param", f"hold_s={raw}"]
    )
    assert code == 2 and "hold_s" in _verdict(err), err
    assert "safe state reached" not in err and "rig event" not in err, err
    assert not any((tmp_path / "o").glob("*.h5"))
