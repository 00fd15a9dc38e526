"""``fbs batch`` (issue 23 part 1): one analysis command over many run files, in parallel.

Proved here, with real processes throughout (the run files come from ``fbs simulate``):
- A: ``fbs batch gap`` over 8 files with ``--jobs 2`` gives, per file, exactly the JSON object
  and exit code of the serial ``fbs gap FILE --json`` run (byte for byte), and so do
  ``inspect`` and ``spectra``; a file the command refuses is its exit 2 and its message;
- resume: a batch SIGTERMed after its first result exits 2 with every finished line intact;
  run again, it skips those and finishes, each file with exactly one result;
- B: the same batch on a real Dask cluster (``dask scheduler`` + two ``dask worker``
  processes on localhost) gives the same results as the local pool;
- C: a worker SIGKILLed mid-batch loses no finished result and the batch completes on the other;
- bad inputs are refused with exit 2 and a message naming the value, before anything is written.

The files are nominal-model runs (95 s at 50 Hz, gimbal bearings off): the gap workflow on them
takes about a second, where a file with an effect to name takes half a minute. Timeouts here are
hang guards, never timing assertions.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from fbs.cli import main
from tests.fbs.commands import FBS
from tests.result_schema import assert_valid_result

pytestmark = pytest.mark.slow
HANG_S = 180  # a hang guard, not a timing assertion
N_FILES = 8
GAP_ARGS = ["--axis", "X"]  # simulate writes no axis attribute
NOMINAL = '[bearing.X]\nmodel = "none"\n[bearing.Y]\nmodel = "none"\n[bearing.Z]\nmodel = "none"\n'


def fbs(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*FBS, *args], capture_output=True, text=True, cwd=cwd, timeout=HANG_S)


def lines_of(path: Path) -> list[dict]:
    return [json.loads(ln) for ln in path.read_text().splitlines()]


def without_elapsed(rec: dict) -> dict:
    """A record but for how long it took and when its result was made (a result names its time)."""
    out = {k: v for k, v in rec.items() if k != "elapsed_s"}
    if isinstance(out.get("result"), dict):
        out["result"] = {k: v for k, v in out["result"].items() if k != "time"}
    return out


def by_file(recs: list[dict]) -> dict[str, dict]:
    out = {r["file"]: without_elapsed(r) for r in recs}
    assert len(out) == len(recs), "a file has more than one line"
    return out


def wait_for_lines(out: Path, p: subprocess.Popen, n: int = 1) -> None:
    """Poll ``out`` until it holds ``n`` whole lines (hang guard only)."""
    t_end = time.monotonic() + HANG_S
    while time.monotonic() < t_end:
        if out.exists() and out.read_bytes().count(b"\n") >= n:
            return
        if p.poll() is not None:
            raise AssertionError(
                f"the batch ended (exit {p.returncode}) before {n} result(s): {p.stderr.read()}"
            )
        time.sleep(0.05)
    raise AssertionError(f"no result in {out} after {HANG_S} s")


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> list[Path]:
    """8 finished run files from ``fbs simulate`` (in this process: the same code as the command)."""
    d = tmp_path_factory.mktemp("runs")
    (d / "nominal.toml").write_text(NOMINAL)
    paths = []
    for seed in range(1, N_FILES + 1):
        p = d / f"run{seed}.h5"
        assert (
            main(
                [
                    "simulate",
                    "--mode",
                    "3",
                    "--duration",
                    "95",
                    "--rate",
                    "50",
                    "--seed",
                    str(seed),
                    "--sim-config",
                    str(d / "nominal.toml"),
                    "--out",
                    str(p),
                ]
            )
            == 0
        )
        paths.append(p)
    return paths


@pytest.fixture(scope="module")
def serial(runs) -> dict[str, tuple[int, str]]:
    """``fbs gap FILE --json`` run by run: exit code and stdout."""
    out = {}
    for p in runs:
        r = fbs("gap", str(p), "--json", *GAP_ARGS)
        out[str(p)] = (r.returncode, r.stdout.strip())
    return out


@pytest.fixture(scope="module")
def local(runs, tmp_path_factory) -> tuple[subprocess.CompletedProcess[str], Path]:
    out = tmp_path_factory.mktemp("local") / "results.jsonl"
    return fbs(
        "batch",
        "gap",
        *map(str, runs),
        "--jobs",
        "2",
        "--args",
        " ".join(GAP_ARGS),
        "--out",
        str(out),
    ), out


# ---------------------------------------------------------------------------- A: the same as serial runs
def test_batch_gap_gives_what_serial_runs_give(local, serial, runs):
    r, out = local
    assert r.returncode == 0, r.stderr
    recs = lines_of(out)
    assert sorted(rec["file"] for rec in recs) == sorted(map(str, runs))  # each file once, absolute
    for rec in recs:
        code, stdout = serial[rec["file"]]
        assert code == 0 and rec["exit"] == 0 and rec["error"] is None
        assert rec["command"] == "gap" and rec["args"] == GAP_ARGS
        # byte for byte, but for when each was made (every result names its time)
        serial_rec, batch_rec = json.loads(stdout), dict(rec["result"])
        assert serial_rec.pop("time") and batch_rec.pop("time")
        assert json.dumps(batch_rec) == json.dumps(serial_rec)
        assert rec["result"]["file"] == rec["file"]
        assert isinstance(rec["elapsed_s"], float) and rec["elapsed_s"] >= 0
    assert (
        "0 already done" in r.stderr
        and f"[{N_FILES}/{N_FILES}]" in r.stderr
        and "exit 0" in r.stderr
    )


def test_gap_json_says_what_ran_on_whose_data_and_an_interrupt_says_aborted(
    runs, serial, monkeypatch, capsys
):
    """Issue 37 acceptance A for ``fbs gap --json``: the schema's header (rig, simulated,
    software, verdict) and the workflow's keys, normally (exit 0, "pass") and interrupted (exit
    2, "aborted", every key present with nothing found)."""
    code, stdout = serial[str(runs[0])]
    out = json.loads(stdout)
    assert_valid_result(out)
    assert (code, out["analysis"], out["verdict"], out["status"]) == (0, "gap", "pass", "complete")
    assert out["simulated"] is True and out["software"]["name"] == "fbs-hil"

    def interrupted(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr("procedures.analysis.gap.workflow.analyse", interrupted)
    capsys.readouterr()
    assert main(["gap", str(runs[0]), "--json", *GAP_ARGS]) == 2
    got = json.loads(capsys.readouterr().out)
    assert_valid_result(got)
    assert (got["verdict"], got["status"], got["effect"], got["explained"]) == (
        "aborted",
        "aborted: interrupted",
        None,
        None,
    )


@pytest.mark.parametrize(
    "command, args",
    [
        ("inspect", []),
        ("spectra", ["--channels", "ac_x_ctl,gyro_x"]),
        ("analyze-transfer", ["--from", "ac_x_ctl", "--to", "pa_x"]),
    ],
)
def test_inspect_and_spectra_batches_give_what_serial_runs_give(runs, tmp_path, command, args):
    files = [str(p) for p in runs[:3]]
    out = tmp_path / "r.jsonl"
    r = fbs(
        "batch", command, *files, "--jobs", "2", "--args", " ".join(args) or "", "--out", str(out)
    )
    got = by_file(lines_of(out))
    assert sorted(got) == sorted(files)
    exits = []
    for f in files:
        s = fbs(*command.split("-"), f, "--json", *args)
        # 1: an analysis that measured none of its headline figures (a 95 s record at 50 Hz
        # resolves no network corner on some seeds); the batch's exit is the worst of its files'
        assert s.returncode in (0, 1), s.stderr
        exits.append(s.returncode)
        # the same object but for when each was made (an analysis's result names its time:
        # ``without_elapsed`` left it out of the batch's)
        serial, batch = json.loads(s.stdout), dict(got[f]["result"])
        serial.pop("time", None)
        assert json.dumps(batch) == json.dumps(serial)
    assert r.returncode == max(exits), r.stderr
    if command == "spectra":
        assert got[files[0]]["result"]["channels"]["gyro_x"]["octave_bands"] > 3


def test_a_refused_file_is_the_commands_exit_and_message(runs, tmp_path):
    short, junk = tmp_path / "short.h5", tmp_path / "junk.h5"
    assert (
        main(["simulate", "--mode", "3", "--duration", "5", "--rate", "50", "--out", str(short)])
        == 0
    )
    junk.write_text("not HDF5\n")
    out = tmp_path / "r.jsonl"
    r = fbs(
        "batch",
        "gap",
        str(short),
        str(junk),
        str(runs[0]),
        "--args",
        " ".join(GAP_ARGS),
        "--out",
        str(out),
    )
    assert r.returncode == 2, r.stderr  # some file failed
    got = by_file(lines_of(out))
    for f in (short, junk):
        s = fbs("gap", str(f), "--json", *GAP_ARGS)
        assert s.returncode == 2 and s.stdout == ""
        assert got[str(f)]["exit"] == 2 and got[str(f)]["result"] is None
        assert s.stderr.strip() == f"fbs gap: error: {got[str(f)]['error']}"
    assert got[str(runs[0])]["exit"] == 0
    assert "2 with an error" in r.stderr


# ---------------------------------------------------------------------------- resume
def test_an_interrupted_batch_keeps_its_results_and_resumes(runs, local, tmp_path):
    out = tmp_path / "r.jsonl"
    argv = [
        *FBS,
        "batch",
        "gap",
        *map(str, runs),
        "--jobs",
        "1",
        "--args",
        " ".join(GAP_ARGS),
        "--out",
        str(out),
    ]
    with subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) as p:
        try:
            wait_for_lines(out, p)
            p.send_signal(signal.SIGTERM)
            _, err = p.communicate(timeout=HANG_S)
        finally:
            p.kill()
    assert p.returncode == 2 and "interrupted" in err, err
    kept = out.read_bytes()
    assert kept.endswith(b"\n")  # whole lines only
    first = lines_of(out)
    assert 1 <= len(first) < N_FILES

    r = fbs(*argv[3:])
    assert r.returncode == 0, r.stderr
    assert f"{len(first)} already done in {out} (skipped)" in r.stderr
    assert out.read_bytes().startswith(kept)  # nothing finished was lost or rewritten
    assert by_file(lines_of(out)) == by_file(lines_of(local[1]))  # each file once, the same results

    again = fbs(*argv[3:])  # all done: nothing to run, the same exit
    assert (
        again.returncode == 0
        and f"{N_FILES} already done" in again.stderr
        and "nothing to run" in again.stderr
    )
    assert out.read_bytes().count(b"\n") == N_FILES


# ---------------------------------------------------------------------------- bad inputs
def _refused(capsys, argv: list[str]) -> str:
    assert main(["batch", *argv]) == 2
    return capsys.readouterr().err


@pytest.mark.parametrize(
    "case",
    [
        "command",
        "no-files",
        "missing",
        "fifo",
        "jobs-0",
        "jobs-word",
        "out-dir",
        "out-missing-dir",
        "out-not-results",
        "out-other-command",
        "out-other-args",
        "args-unknown",
        "args-shared-output",
    ],
)
def test_bad_inputs_are_refused_before_anything_is_written(runs, tmp_path, capsys, case):
    f = str(runs[0])
    out = tmp_path / "r.jsonl"
    other = (
        '{"file": "/x.h5", "command": "inspect", "args": [], "exit": 0, "result": {}, '
        '"error": null, "elapsed_s": 0.1}\n'
    )
    if case in ("out-not-results",):
        out.write_text("a,b,c\n1,2,3\n")
    if case in ("out-other-command",):
        out.write_text(other)
    if case in ("out-other-args",):
        out.write_text(other.replace('"inspect"', '"gap"'))
    if case == "fifo":
        os.mkfifo(tmp_path / "pipe.h5")
    before = out.read_bytes() if out.exists() else None
    argv, named = {
        "command": (["gapp", f], "'gapp'"),
        "no-files": (["gap"], "no FILE"),
        "missing": (["gap", f, str(tmp_path / "nope.h5")], "nope.h5 (does not exist)"),
        "fifo": (["gap", str(tmp_path / "pipe.h5")], "pipe.h5 (not a regular file)"),
        "jobs-0": (["gap", f, "--jobs", "0"], "--jobs '0' must be at least 1"),
        "jobs-word": (["gap", f, "--jobs", "two"], "--jobs 'two' is not a whole number"),
        "out-dir": (["gap", f, "--out", str(tmp_path)], f"--out {tmp_path} is not a regular file"),
        "out-missing-dir": (
            ["gap", f, "--out", str(tmp_path / "no" / "r.jsonl")],
            f"{tmp_path / 'no'} does not exist",
        ),
        "out-not-results": (["gap", f], "not a batch results file (line 1 is not JSON)"),
        "out-other-command": (
            ["gap", f],
            "holds results of `fbs batch inspect`, not `fbs batch gap`",
        ),
        "out-other-args": (["gap", f, "--args", "--axis X"], "made with --args '', not '--axis X'"),
        "args-unknown": (
            ["gap", f, "--args", "--frobnicate 3"],
            "unrecognized arguments: --frobnicate 3",
        ),
        "args-shared-output": (
            ["gap", f, "--args", f"--report {tmp_path / 'rep'}"],
            "--report would send",
        ),
    }[case]
    if "--out" not in argv:
        argv += ["--out", str(out)]
    err = _refused(capsys, argv)
    assert err.startswith("fbs batch: error: ") and named in err, err
    assert (out.read_bytes() if out.exists() else None) == before  # nothing written
    assert not (tmp_path / "rep").exists() and not (tmp_path / "no").exists()


def test_scheduler_without_distributed_names_the_extra(runs, tmp_path):
    out = tmp_path / "r.jsonl"
    code = (
        "import sys; sys.modules['distributed'] = None; from fbs.cli import main; "
        f"sys.exit(main(['batch', 'inspect', {str(runs[0])!r}, '--scheduler', 'tcp://127.0.0.1:8786', "
        f"'--out', {str(out)!r}]))"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=HANG_S)
    assert r.returncode == 2, r.stderr
    assert "fbs-hil[cluster]" in r.stderr and "distributed" in r.stderr
    assert not out.exists()


# ---------------------------------------------------------------------------- B, C: a Dask cluster on localhost
# (the ``cluster`` fixture: tests/fbs/conftest.py)
def test_b_a_dask_cluster_gives_the_local_results(runs, local, cluster, tmp_path):
    out = tmp_path / "r.jsonl"
    r = fbs(
        "batch",
        "gap",
        *map(str, runs),
        "--scheduler",
        cluster.address,
        "--args",
        " ".join(GAP_ARGS),
        "--out",
        str(out),
    )
    assert r.returncode == 0, r.stderr
    assert f"Dask scheduler {cluster.address} (2 workers, 2 threads)" in r.stderr
    assert by_file(lines_of(out)) == by_file(lines_of(local[1]))


def test_c_a_worker_killed_mid_batch_loses_nothing(runs, local, cluster, tmp_path):
    out = tmp_path / "r.jsonl"
    argv = [
        *FBS,
        "batch",
        "gap",
        *map(str, runs),
        "--scheduler",
        cluster.address,
        "--args",
        " ".join(GAP_ARGS),
        "--out",
        str(out),
    ]
    with subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) as p:
        try:
            wait_for_lines(out, p)
            kept = out.read_bytes()
            cluster.kill(cluster.workers[0])  # the worker and its nanny, without warning
            _, err = p.communicate(timeout=HANG_S)
        finally:
            p.kill()
    assert p.returncode == 0, err
    assert out.read_bytes().startswith(kept[: kept.rindex(b"\n") + 1])
    assert by_file(lines_of(out)) == by_file(lines_of(local[1]))  # each file once, the same results
    assert cluster.n_workers() == 1


def test_a_record_exits_as_the_single_command_would():
    """A result whose verdict is "fail" exits 1 as `fbs analyze` does (it said 0); a bug is an
    "internal error", exit 2, as ``fbs.cli.main`` ends it (it said 1, "limits failed")."""
    from fbs.batch_task import guarded

    assert guarded(lambda: {"verdict": "fail"})[0] == 1
    assert guarded(lambda: {"verdict": "pass"})[0] == 0
    assert guarded(lambda: {"verdict": "aborted"})[0] == 2
    assert guarded(lambda: {"effects": []})[0] == 0
    code, result, error, _ = guarded(lambda: 1 / 0)
    assert code == 2 and result is None and error.startswith("internal error: ZeroDivisionError")
