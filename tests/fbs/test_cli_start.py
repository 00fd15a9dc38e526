"""Issue 37 items 9 and 10: a command line that starts fast and says what happened.

* The parser (``fbs --version``, ``--help``, a usage error) imports no numerics, no rig and no
  UI: each command loads its implementation when it runs (``fbs.cli.COMMANDS``). Checked by
  the modules loaded, never by time (``bench/cli_start.py`` times it).
* A reader that leaves early (``fbs ... | head``): no traceback, exit 2.
* ``--param NAME`` without ``=VALUE`` is a usage error (64), not a bad value (2).
* A defect: one line saying so, with where its traceback is; the traceback on stderr with ``-v``.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

import fbs.inspect
from fbs.cli import COMMANDS, build_parser, load, main
from fbs.usage import EXIT_ERROR, EXIT_USAGE
from tests.fbs.commands import FBS

ROOT = Path(__file__).parents[2]
#: what the parser must not load: numerics, HDF5, plots, CAN, the UI, the cluster, the plant,
#: and this project's rig and runner (they load numpy and h5py)
HEAVY_PACKAGES = {
    "numpy",
    "scipy",
    "numba",
    "h5py",
    "matplotlib",
    "can",
    "canopen",
    "textual",
    "dask",
    "distributed",
    "allantools",
    "simhw",
    "daq",
}
HEAVY_MODULES = {
    "drivers.rig",
    "procedures.runner",
    "procedures.procedure",
    "procedures.params",
    "console.app",
}


def _python(code: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=ROOT,
    )


USAGE_ERRORS = [["run", "stopwatch", "--no-such-option"], ["no-such-command"]]


@pytest.mark.parametrize(
    "argv", [["--version"], ["--help"], ["run", "--help"], ["simulate", "--help"], *USAGE_ERRORS]
)
def test_the_parser_loads_no_heavy_module(argv):
    r = _python(f"""
        import sys
        from fbs.cli import main
        try:
            main({argv!r})
        except SystemExit as exc:
            print("exit", exc.code)
        heavy = {sorted(HEAVY_PACKAGES)!r}
        print("loaded:", sorted(m for m in sys.modules
                                if m.split(".")[0] in heavy or m in {sorted(HEAVY_MODULES)!r}))
    """)
    assert "loaded: []" in r.stdout, r.stdout[-2000:] + r.stderr[-2000:]
    assert f"exit {EXIT_USAGE if argv in USAGE_ERRORS else 0}" in r.stdout, r.stdout[-500:]


def test_the_registry_names_every_command_and_what_each_loads():
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    assert list(sub.choices) == list(COMMANDS)
    load(*COMMANDS)  # every module a command loads exists (the bench, batch workers load them)
    assert "procedures.calibrations.stopwatch" in sys.modules  # "package.*": each of its modules


def test_a_reader_that_leaves_early_ends_it_quietly_with_exit_2():
    """``fbs run stopwatch --help | head`` ended in a BrokenPipeError traceback, exit 1. The
    pipe's reading end is closed before the child writes: every write to it fails."""
    with subprocess.Popen(
        [*FBS, "run", "stopwatch", "--help"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=ROOT,
    ) as p:
        assert p.stdout is not None and p.stderr is not None
        p.stdout.close()
        err = p.stderr.read()
        assert p.wait(timeout=600) == EXIT_ERROR, err
    assert err == "", err


def test_a_param_without_a_value_is_a_usage_error(capsys, tmp_path):
    """``--param repetitions`` exited 2 (a bad value); the command line itself is wrong: 64."""
    for bad in ("repetitions", "=4", " =4"):
        with pytest.raises(SystemExit) as exc:
            main(["run", "stopwatch", "--out", str(tmp_path), "--param", bad])
        err = capsys.readouterr().err
        assert exc.value.code == EXIT_USAGE, err
        assert "argument --param" in err and "NAME=VALUE" in err, err
    assert not list(tmp_path.iterdir())


def _defect(path, max_events):
    raise RuntimeError("a defect")


def test_a_defect_is_one_line_and_its_traceback_is_shown_with_v(capsys, monkeypatch, tmp_path):
    """Without ``-v``: one line, "internal error", please report, how to see the traceback; with
    ``-v``: the traceback on stderr above that line. Exit 2 both ways."""
    rec = tmp_path / "r.h5"
    assert (
        main(["simulate", "--mode", "3", "--duration", "1", "--rate", "100", "--out", str(rec)])
        == 0
    )
    capsys.readouterr()
    monkeypatch.setattr(fbs.inspect, "describe", _defect)
    assert main(["inspect", str(rec)]) == EXIT_ERROR
    err = capsys.readouterr().err
    assert "Traceback" not in err and err.count("\n") == 1, err
    assert "fbs inspect: internal error: RuntimeError: a defect" in err, err
    assert "please report" in err, err
    assert "`fbs -v inspect ...` shows its traceback" in err, err
    assert main(["-v", "inspect", str(rec)]) == EXIT_ERROR
    err = capsys.readouterr().err
    assert "Traceback (most recent call last)" in err and "in _defect" in err, err
    assert err.rstrip().endswith("its traceback is above)"), err


@pytest.mark.slow
def test_a_defect_in_a_run_leaves_its_traceback_in_the_runs_log(capsys, monkeypatch, tmp_path):
    """A run has a log: the traceback goes there and the one line names it."""
    import fbs.run_progress

    def broken(*args, **kwargs):
        raise RuntimeError("a defect in the run")

    monkeypatch.setattr(fbs.run_progress, "run_procedure", broken)
    code = main(["run", "stopwatch", "--rig", "sim?warm=1&watchdog=5", "--out", str(tmp_path)])
    assert code == EXIT_ERROR
    err = capsys.readouterr().err
    log = tmp_path / "stopwatch.log"
    assert "Traceback" not in err and f"its traceback is in {log}" in err, err
    text = log.read_text()
    assert "Traceback (most recent call last)" in text, text[-2000:]
    assert "a defect in the run" in text, text[-2000:]


def test_a_command_runs_one_blas_thread_unless_its_environment_says():
    """OpenBLAS's threads on a busy box made ``fbs gap`` take 2.2x the wall time of one thread
    (``fbs.cli``'s docstring): a command sets one before it loads numpy, unless already set."""
    pytest.importorskip("threadpoolctl")  # `make test` installs it (the cluster extra)
    r = _python("""
        import os
        for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS"):
            os.environ.pop(var, None)
        os.environ["MKL_NUM_THREADS"] = "3"
        from fbs.cli import main
        code = main(["inspect", "/nonexistent/run.h5"])  # loads numpy, then fails
        print("exit", code, os.environ.get("OPENBLAS_NUM_THREADS"), os.environ["MKL_NUM_THREADS"])
        from threadpoolctl import threadpool_info
        blas = [i["num_threads"] for i in threadpool_info() if i["internal_api"] == "openblas"]
        print("openblas", blas)
    """)
    out = r.stdout + r.stderr[-2000:]
    assert "exit 2 1 3" in r.stdout, out
    assert "openblas [1]" in r.stdout, out
