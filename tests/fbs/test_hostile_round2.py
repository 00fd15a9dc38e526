"""Issue 36 (round 2 of the hostile-input campaign), the cases fixed so far, each through
``fbs.cli.main`` as a script would call the command: an error names the value and its limit,
exits 2 (never 1, which says "limits failed"), opens no output and shows no traceback."""

from __future__ import annotations

import json
import os

import pytest

import fbs.inspect
from fbs.cli import main
from procedures.params import find_prior


@pytest.fixture(scope="module")
def record(tmp_path_factory):
    path = tmp_path_factory.mktemp("rec") / "s.h5"
    assert (
        main(["simulate", "--mode", "3", "--duration", "2", "--rate", "100", "--out", str(path)])
        == 0
    )
    return path


def _fails(capsys, argv: list[str], *needles: str) -> str:
    code = main(argv)
    err = capsys.readouterr().err
    assert code == 2, err
    assert "Traceback" not in err, err
    for n in needles:
        assert n in err, err
    return err


def test_resume_from_a_file_no_procedure_wrote_is_an_error_not_a_traceback(
    capsys, record, tmp_path
):
    """Item 1: ``ProcedureError`` reached the shell as a traceback and exit 1."""
    _fails(
        capsys,
        ["run", "stopwatch", "--resume", str(record), "--out", str(tmp_path / "o")],
        "fbs run: error:",
        "not a procedure run",
    )


def test_a_stray_json_in_the_output_folder_is_not_a_prior_result(tmp_path):
    """Item 6: ``{"procedure": ..., "verdict": "pass"}`` without values crashed with KeyError."""
    (tmp_path / "notes.json").write_text(json.dumps({"procedure": "earth-rate", "verdict": "pass"}))
    (tmp_path / "other.json").write_text(
        json.dumps({"procedure": ["x"], "verdict": "pass", "values": {}})
    )
    assert find_prior(tmp_path) == {}
    with pytest.raises(ValueError, match="not a procedure summary"):
        find_prior(tmp_path, [str(tmp_path / "notes.json")])


@pytest.mark.parametrize(
    "option, needle",
    [
        (["--period", "0"], "--period 0.0 must be a finite number > 0"),
        (["--period", "inf"], "--period inf must be"),
        (["--seg-s", "1e-9"], "at least 8 samples"),
        (["--period", "0.01"], "at least 8 samples"),
        (["--blocks", "1"], "--blocks 1 must be at least 2"),
        (["--lo-hz", "nan"], "--lo-hz nan must be"),
    ],
)
def test_transfer_options_out_of_range_are_refused_by_name(capsys, record, option, needle):
    """Item 5: ``--period 0`` was a ZeroDivisionError, ``--seg-s 1e-9`` too."""
    _fails(
        capsys,
        ["analyze", "transfer", str(record), "--from", "ac_x_ctl", "--to", "pa_x", *option],
        needle,
    )


def test_an_output_naming_a_folder_is_refused_and_nothing_is_written(capsys, tmp_path):
    """Item 12: ``--out newdir/`` wrote a file named ``newdir``."""
    _fails(
        capsys,
        [
            "simulate",
            "--mode",
            "3",
            "--duration",
            "1",
            "--rate",
            "100",
            "--out",
            f"{tmp_path}/newdir/",
        ],
        "names a folder",
    )
    assert not (tmp_path / "newdir").exists()


def test_a_negative_event_count_is_refused(capsys, record):
    """Item 12: ``--max-events -1`` printed "... 2 more" for one event."""
    _fails(capsys, ["inspect", str(record), "--max-events", "-1"], "--max-events -1 must be >= 0")
    _fails(
        capsys,
        ["inspect", str(record), "--json", "--max-events", "-1"],
        "--max-events -1 must be >= 0",
    )


def test_a_defect_is_an_internal_error_with_exit_2_not_1(capsys, record, monkeypatch):
    """The one handler: an exception no command expects is said to be this program's defect,
    its traceback logged, and the exit code is 2 (1 is reserved for "limits failed")."""

    def broken(path, max_events):
        raise RuntimeError("a defect")

    monkeypatch.setattr(fbs.inspect, "describe", broken)
    code = main(["inspect", str(record)])
    err = capsys.readouterr().err
    assert code == 2 and "fbs inspect: internal error: RuntimeError: a defect" in err, err


def test_a_sim_config_path_is_data_not_url_text(tmp_path):
    """Item 3: with files ``inj.toml&warm=1`` and ``inj.toml`` both present, the run used
    ``inj.toml`` and also started warm. The path is %-escaped into the URL and read back whole."""
    import argparse
    from urllib.parse import parse_qsl, urlsplit

    from fbs.run import rig_url

    odd = tmp_path / "inj.toml&warm=1#x?y"
    url = rig_url(argparse.Namespace(rig="sim?seed=2", sim_config=str(odd)))
    params = dict(parse_qsl(urlsplit(url).query))
    assert params == {"seed": "2", "config": str(odd)}


def test_a_fifo_as_sim_config_is_refused_not_waited_on(capsys, tmp_path):
    """Item 10: ``fbs simulate --sim-config FIFO`` waited forever (nothing writes the FIFO)."""
    import os

    fifo = tmp_path / "cfg.toml"
    os.mkfifo(fifo)
    _fails(
        capsys,
        [
            "simulate",
            "--mode",
            "3",
            "--duration",
            "1",
            "--rate",
            "100",
            "--sim-config",
            str(fifo),
            "--out",
            str(tmp_path / "x.h5"),
        ],
        "not a regular file",
    )
    assert not (tmp_path / "x.h5").exists()


def test_an_earlier_gap_report_is_not_replaced_without_force(capsys, record, tmp_path):
    """Item 10: ``fbs gap --report DIR`` overwrote an existing ``model_before.h5``."""
    (tmp_path / "model_before.h5").write_bytes(b"an earlier report's")
    _fails(
        capsys,
        ["gap", str(record), "--report", str(tmp_path)],
        "already holds model_before.h5",
        "--force",
    )
    assert (tmp_path / "model_before.h5").read_bytes() == b"an earlier report's"


def test_a_results_file_belongs_to_one_batch_at_a_time(capsys, record, tmp_path):
    """Item 9: two ``fbs batch`` runs with different commands on one ``--out`` both exited 0 and
    mixed their lines. While one holds the results file, another is refused and writes nothing."""
    from fbs.batch_exec import ResultsFile

    out = tmp_path / "results.jsonl"
    holder = ResultsFile(out)  # a batch at work on it
    try:
        _fails(
            capsys,
            ["batch", "inspect", str(record), "--jobs", "1", "--out", str(out)],
            "being written by another `fbs batch`",
        )
        assert out.read_bytes() == b""
    finally:
        holder.close()
    assert main(["batch", "inspect", str(record), "--jobs", "1", "--out", str(out)]) == 0
    assert len(out.read_text().splitlines()) == 1


@pytest.mark.parametrize(
    "argv, needle",
    [
        (
            ["simulate", "--mode", "3", "--duration", "1", "--rate", "100", "--seed", "-1"],
            "seed -1 must be a whole number 0..9223372036854775807",
        ),
        (
            ["record", "--rig", "sim?seed=-1", "--mode", "3", "--duration", "1", "--rate", "100"],
            "rig URL 'sim?seed=-1': seed='-1' must be a whole number 0..",
        ),
        (
            ["record", "--rig", "sim?seed=nan", "--mode", "3", "--duration", "1", "--rate", "100"],
            "seed='nan' must be a whole number 0..",
        ),
    ],
)
def test_a_seed_out_of_range_is_refused_by_value_and_limit(capsys, tmp_path, argv, needle):
    """Item 12: ``--seed -1`` said "expected non-negative integer" (numpy's words)."""
    _fails(capsys, [*argv, "--out", str(tmp_path / "s.h5")], needle)
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize(
    "command",
    [
        ["run", "stopwatch"],
        ["simulate", "--mode", "3", "--duration", "1", "--rate", "100"],
        ["demo"],
    ],
)
def test_a_file_in_the_way_of_the_output_folder_is_named_before_the_rig_opens(
    capsys, tmp_path, command
):
    """Item 12: ``--out FILE`` said "[Errno 17] File exists", and `fbs run` said it only after the
    rig had been opened and made safe."""
    (tmp_path / "afile").write_text("mine")
    out = (
        str(tmp_path / "afile")
        if command[0] in ("run", "demo")
        else str(tmp_path / "afile" / "s.h5")
    )
    err = _fails(capsys, [*command, "--out", out], "afile", "is a file, not a folder")
    assert "rig event" not in err and "safe state" not in err, err
    assert (tmp_path / "afile").read_text() == "mine"


def test_a_fifo_as_prior_or_among_the_summaries_is_refused_not_waited_on(capsys, tmp_path):
    """A FIFO given as ``--prior`` (or named ``*.json`` in ``--out``) blocked the read forever."""
    fifo = tmp_path / "p.json"
    os.mkfifo(fifo)
    assert find_prior(tmp_path) == {}
    _fails(
        capsys,
        ["run", "stopwatch", "--prior", str(fifo), "--out", str(tmp_path / "o")],
        f"--prior {fifo}: not a regular file",
    )
