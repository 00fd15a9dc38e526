"""Issue 40 item 6: every ``fbs ...`` command example in README.md and docs/**/*.md is one that
``fbs``'s own parser takes, and the cheap ones run.

An example is an inline code span that starts ``fbs `` or a code line (indented or fenced) that
does, its continuation lines joined. Usage lines are read as usage: ``[...]`` is optional,
``a|b`` are alternatives (each must be valid), ``...`` is "more of the same", and an upper-case
word (``FILE.h5``, ``S``, ``NAME=VALUE``) is a placeholder. Each example's command words must be
commands, its options options of that command, and every concrete value one the option takes
(its type, its choices); then the whole line, placeholders filled with values of the right type,
goes through ``parse_args`` (required arguments aside: prose quotes fragments). The examples of
``fbs --version``, ``simulate``, ``inspect``, ``spectra``, ``recover`` and ``analyze`` are then
run for real in a temporary directory, their required arguments only, placeholders filled with
a file simulated there and short durations.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import re
import shlex
import shutil
from dataclasses import dataclass
from pathlib import Path

import pytest

from fbs.cli import build_parser, main

ROOT = Path(__file__).resolve().parents[2]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
#: a placeholder: an upper-case word standing alone (``FILE``, ``S``, ``P=LO:HI:N``)
PLACEHOLDER = re.compile(r"(?<![\w])[A-Z][A-Z0-9_]*(?![\w])")
#: the extensions docs/procedures/writing.md adds as its examples
GUIDE_EXAMPLES = ("ac-noise", "pickoff_hum")
#: commands cheap enough to run for every example of theirs
RUN = ("--version", "simulate", "inspect", "spectra", "recover", "analyze")


@dataclass(frozen=True)
class Example:
    where: str  # file:line
    text: str  # the command line, "fbs ..."

    def __str__(self) -> str:
        return f"{self.where}: {self.text}"


def _command_part(line: str) -> str:
    """A code line's command without the description after it (two or more spaces)."""
    return re.split(r"\s{2,}|\s+#\s", line.strip(), maxsplit=1)[0].rstrip("\\ ").strip()


def examples() -> list[Example]:
    found: list[Example] = []
    for path in DOCS:
        rel = path.relative_to(ROOT)
        lines = path.read_text().splitlines()
        fenced = False
        i = 0
        while i < len(lines):
            line = lines[i]
            if line.lstrip().startswith("```"):
                fenced = not fenced
            code = fenced or line.startswith("    ")
            if code and line.strip().startswith("fbs "):
                text = line.strip()
                indent = len(line) - len(line.lstrip())
                # continuations: a trailing backslash, or the next lines indented deeper
                while i + 1 < len(lines) and (
                    text.endswith("\\")
                    or (
                        lines[i + 1].strip()
                        and len(lines[i + 1]) - len(lines[i + 1].lstrip()) > indent
                        and lines[i + 1].strip().startswith(("[", "--"))
                    )
                ):
                    i += 1
                    text = _command_part(text) + " " + lines[i].strip()
                for part in text.split(";"):
                    if part.strip().startswith("fbs "):
                        found.append(Example(f"{rel}:{i + 1}", _command_part(part)))
            elif not code:
                for m in re.finditer(r"`(fbs [^`]+)`", line):
                    found.append(Example(f"{rel}:{i + 1}", m.group(1).strip()))
            i += 1
    # "fbs CMD: error: ..." and "fbs console: rig closed ...": what fbs prints, not commands;
    # "fbs ... | head": any command; the guide's examples exist once the guide's example is
    # added (tests/test_extension_points.py runs them so)
    return [
        e
        for e in found
        if not re.match(r"fbs ([\w-]+:|\.\.\.)", e.text)
        and not any(name in e.text for name in GUIDE_EXAMPLES)
    ]


def _tokens(text: str) -> list[str]:
    """The words of a usage line: brackets dropped (optional parts kept), ``...`` dropped."""
    text = re.sub(r"(?<=\S)\[([^\]\s]*)\]", r"\1", text)  # name:k=v[,axis=Y]
    text = text.replace("[", " ").replace("]", " ")
    try:
        words = shlex.split(text)[1:]
    except ValueError:
        words = text.split()[1:]
    out = []
    for w in words:
        w = w.removesuffix("...").strip("'\"")
        if w and w not in ("...", "|"):
            out.append(w)
    return out


def _convert(action: argparse.Action, value: str) -> object:
    """``value`` as argparse reads it for ``action``: its type, then its choices; raises."""
    got = action.type(value) if callable(action.type) else value
    if action.choices is not None and got not in action.choices:
        raise ValueError(f"not one of {list(action.choices)}")
    return got


def _value(action: argparse.Action, value: str, ex: Example) -> str | None:
    """``value`` checked against ``action`` (each of its ``a|b`` alternatives); the value to
    parse with, or None where a placeholder cannot be filled with one of the right type."""
    alternatives = value.split("|") if "|" in value and not value.startswith("|") else [value]
    name, eq, _ = alternatives[0].partition("=")
    if eq:  # "mode=3|4|5"
        alternatives[1:] = [a if "=" in a else f"{name}={a}" for a in alternatives[1:]]
    chosen: str | None = None
    for alt in alternatives:
        try:
            _convert(action, alt)
        except (TypeError, ValueError, argparse.ArgumentTypeError) as exc:
            if not PLACEHOLDER.search(alt):
                raise AssertionError(f"{ex}: {alt!r} is not a valid value ({exc})") from None
            if action.choices is not None:
                alt = str(next(iter(action.choices)))
            elif action.type in (int, float):
                alt = "1"
            else:
                return None  # a placeholder for a value only the command's own type reads
        chosen = alt if chosen is None else chosen
    return chosen


def _subparsers(parser: argparse.ArgumentParser) -> argparse._SubParsersAction | None:
    return next((a for a in parser._actions if isinstance(a, argparse._SubParsersAction)), None)


def normalise(ex: Example, parser: argparse.ArgumentParser) -> list[str] | None:
    """The example as an argv for ``parser``, every word checked against its actions; None
    where a placeholder cannot be filled (the checks have been made)."""
    words = _tokens(ex.text)
    argv: list[str] = []
    fillable = True
    p = parser
    positionals = [a for a in p._actions if not a.option_strings]
    i = 0
    while i < len(words):
        w = words[i]
        i += 1
        if w.startswith("-"):
            opt, eq, inline = w.partition("=")
            action = p._option_string_actions.get(opt)
            assert action is not None, f"{ex}: {p.prog} has no option {opt}"
            if action.nargs == 0:
                argv.append(opt)
                continue
            if not eq and (i == len(words) or words[i].startswith("-")):
                continue  # prose naming the option ("`fbs run --param`"), not a use of it
            argv.append(opt)
            values = [inline] if eq else []
            if not eq:
                many = action.nargs in ("+", "*", argparse.REMAINDER)
                while i < len(words) and not words[i].startswith("-"):
                    values.append(words[i])
                    i += 1
                    if not many:
                        break
            for v in values:
                got = _value(action, v, ex)
                fillable &= got is not None
                argv.append(got or v)
            continue
        assert positionals, f"{ex}: {p.prog} takes no argument {w!r}"
        action = positionals[0]
        if isinstance(action, argparse._SubParsersAction):
            names = w.split("|")
            if all(PLACEHOLDER.fullmatch(n) for n in names):  # "fbs COMMAND FILE --json"
                return None  # any command: nothing more to check
            for n in names:
                assert n in action.choices, f"{ex}: {p.prog} has no command {n!r}"
            argv.append(names[0])
            p = action.choices[names[0]]
            positionals = [a for a in p._actions if not a.option_strings]
            continue
        got = _value(action, w, ex)
        fillable &= got is not None
        argv.append(got or w)
        if action.nargs not in ("+", "*", argparse.REMAINDER):
            positionals.pop(0)
    return argv if fillable else None


def _optional_everywhere(parser: argparse.ArgumentParser) -> None:
    """Every argument of every (sub)command not required: prose quotes fragments."""
    for action in parser._actions:
        action.required = False
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                _optional_everywhere(sub)


EXAMPLES = examples()


def test_the_docs_have_command_examples_of_every_kind():
    texts = [e.text for e in EXAMPLES]
    assert len(texts) > 60, len(texts)
    for command in ("--version", "simulate", "run", "gap", "campaign", "batch", "inspect"):
        assert any(t.split()[1] == command for t in texts), command


@pytest.mark.parametrize("ex", EXAMPLES, ids=[e.where for e in EXAMPLES])
def test_every_command_example_parses(ex):
    parser = build_parser()
    _optional_everywhere(parser)
    argv = normalise(ex, parser)
    if argv is None:
        return  # checked word by word; a placeholder only the command's own type reads
    out = io.StringIO()
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(out):
            parser.parse_args(argv)
    except SystemExit as exc:  # --help and --version end the parse, with exit 0
        assert exc.code == 0, f"{ex}: {argv} does not parse: {out.getvalue()[-500:]}"


# ---------------------------------------------------------------------------- run the cheap ones
def _runnable(ex: Example) -> bool:
    """An example of a cheap command that is a whole command (prose quotes fragments: `fbs
    simulate --truth`), as ``fbs``'s parser says with its required arguments."""
    words = ex.text.split()
    if words[1] not in RUN:
        return False
    out = io.StringIO()
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(out):
            build_parser().parse_args(_fill(ex.text, Path("in.h5"), Path("work")))
    except SystemExit as exc:
        return exc.code == 0
    return True


def _required_only(text: str) -> str:
    """The usage line without its optional parts (``[...]``, nested too)."""
    while True:
        shorter = re.sub(r"\[[^\[\]]*\]", " ", text)
        if shorter == text:
            return " ".join(text.split())
        text = shorter


def _fill(text: str, sim: Path, work: Path) -> list[str]:
    """A usage line's argv with its placeholders filled for a run in ``work``."""
    argv: list[str] = []
    words = _required_only(text).split()[1:]
    for k, w in enumerate(words):
        prev = words[k - 1] if k else ""
        if "|" in w:
            w = w.split("|")[0]
        if prev == "--duration":
            w = str(min(float(w), 2.0)) if not PLACEHOLDER.search(w) else "2"
        elif prev == "--rate" and PLACEHOLDER.search(w):
            w = "200"
        elif prev == "--out":
            w = str(work / ("out.h5" if w.endswith(".h5") else "out"))
        elif prev in ("--channels",) and not PLACEHOLDER.search(w):
            w = "ac_x_ctl,gyro_x" if w == "a,b" else w
        elif prev == "--channels":
            w = "ac_x_ctl,gyro_x"
        elif prev in ("--from", "--to") and PLACEHOLDER.search(w):
            w = "cmd_x" if prev == "--from" else "ac_x_ctl"
        elif not w.startswith("-") and (w.endswith(".h5") or w in ("FILE", "FILE.h5")):
            w = str(work / f"in{k}.h5")
            if sim.is_file():
                shutil.copy(sim, w)
        argv.append(w)
    return argv


@pytest.fixture(scope="module")
def simulated(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("sim") / "sim.h5"
    code = main(["simulate", "--mode", "3", "--duration", "4", "--rate", "200", "--out", str(path)])
    assert code == 0
    return path


RUNNABLE = [e for e in EXAMPLES if _runnable(e)]


@pytest.mark.parametrize("ex", RUNNABLE, ids=[e.where for e in RUNNABLE])
def test_the_cheap_examples_run(ex, simulated, tmp_path, capsys):
    argv = _fill(ex.text, simulated, tmp_path)
    try:
        code = main(argv)
    except SystemExit as exc:  # --version
        code = exc.code
    err = capsys.readouterr().err
    assert "Traceback" not in err, f"{ex}: {argv}\n{err[-2000:]}"
    if argv[0] == "analyze":
        # a plain mode-3 record is no sweep or excitation: a refusal, not a usage error
        assert code in (0, 1, 2), f"{ex}: {argv} exit {code}\n{err[-1000:]}"
    else:
        assert code == 0, f"{ex}: {argv} exit {code}\n{err[-1000:]}"
