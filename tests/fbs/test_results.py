"""Results people can trust at a glance (issue 37, items 1-3 and acceptance A): every result
names its rig and whether it was simulated, the software and the time; a run with no headline
figure measured is no pass, in the text as in the JSON; every ``--json`` keeps one shape on
every path and follows ``docs/schema/run-summary.schema.json``. (The other procedures' runs are
checked against the schema where their own end-to-end tests run them.)"""

from __future__ import annotations

import hashlib
import json
import re
import subprocess
from pathlib import Path

import pytest

from daq.reader import RunFile
from drivers.rig import Rig, open_rig
from fbs.cli import main
from procedures.calibrations import catalogue
from procedures.procedure import Verdict
from procedures.runner import RunSummary, headline_measurement
from tests.fbs.commands import FBS, RIG, SHORT_STOPWATCH
from tests.result_schema import assert_valid_result

ROOT = Path(__file__).parents[2]
NAN = re.compile(r"\bnan\b")


def fbs(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([*FBS, *args], capture_output=True, text=True, timeout=600)


def _commit() -> str | None:
    r = subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True, text=True)
    return r.stdout.strip() or None


# ---------------------------------------------------------------------------- fast
def test_the_rig_states_whether_it_is_simulated(tmp_path):
    """The sim scheme says so itself, with its config's path and hash; a rig built without a
    scheme saying so (the serial rig's ``assemble``) is hardware."""
    cfg = tmp_path / "site.toml"
    cfg.write_text("[site]\nlatitude_deg = 37.43\n")
    with open_rig("sim") as rig:
        assert rig.simulated is True and rig.sim_config is None
    with open_rig(f"sim?config={cfg}") as rig:
        assert rig.simulated is True
        sha = hashlib.sha256(cfg.read_bytes()).hexdigest()
        assert rig.sim_config == {"path": str(cfg.resolve()), "sha256": sha}
    import inspect

    from drivers.rig import assemble

    assert inspect.signature(Rig).parameters["simulated"].default is False
    assert inspect.signature(assemble).parameters["simulated"].default is False


@pytest.mark.parametrize("name", sorted(catalogue()))
def test_an_aborted_runs_json_keeps_every_figures_shape(name):
    """Item 3: before any analysis every headline figure is {channel: None}, its interval too,
    resolved {K: {channel: False}}; the object names the procedure, status and verdict."""
    proc = catalogue()[name]()
    s = RunSummary(
        name,
        Path(f"/o/{name}.h5"),
        "aborted: interrupted",
        Verdict.ABORTED,
        provenance={
            "rig": "sim",
            "simulated": True,
            "sim_config": None,
            "software": {"name": "fbs-hil", "version": "0", "commit": None},
            "time": "2026-01-01T00:00:00+00:00",
        },
    )
    out = s.json_result(proc)
    assert_valid_result(out)
    assert (out["procedure"], out["status"]) == (name, "aborted: interrupted")
    assert out["verdict"] == "aborted"
    assert proc.headline()
    for k, channels in proc.headline().items():
        assert out[k] == dict.fromkeys(channels) and out[f"{k}_ci95"] == dict.fromkeys(channels)
        assert out["resolved"][k] == dict.fromkeys(channels, False)


def test_no_headline_figure_measured_is_a_failing_measurement():
    """Item 2, the rule: every headline figure None on every channel -> a failing measurement
    that says why; one figure on one channel measured -> no such measurement."""
    proc = catalogue()["drift"]()
    none = {k: dict.fromkeys(ch) for k, ch in proc.headline().items()}
    m = headline_measurement(proc, none)
    assert m is not None and m.passed is False and "not a pass" in m.note
    one = none | {"arw_urad_per_sqrt_s": {"X": 0.01, "Y": None, "Z": None, "XRD": None}}
    assert headline_measurement(proc, one) is None


# ---------------------------------------------------------------------------- end to end
@pytest.mark.slow
def test_provenance_verdict_and_every_commands_json_on_the_sim_rig(tmp_path, monkeypatch, capsys):
    """Items 1-2 and acceptance A for the analysis commands: a one-repetition stopwatch on the
    sim rig with a sim config, no earth-rate result in --out: K_g null on its channel, so exit 1
    "fail" (it was 0 "pass"); the JSON, the summary, the report and the run file name the rig,
    "simulated", the config's hash, the software's version and commit and the time. The text
    says "fail" and "not resolved", never "± nan". Then both analysis commands on its file,
    normally and interrupted, each against the schema."""
    cfg = tmp_path / "site.toml"
    cfg.write_text("[site]\nlatitude_deg = 37.43\n")
    sha = hashlib.sha256(cfg.read_bytes()).hexdigest()
    r = fbs(
        "run",
        "stopwatch",
        "--rig",
        RIG,
        "--sim-config",
        str(cfg),
        "--out",
        str(tmp_path),
        "--json",
        *SHORT_STOPWATCH,
    )
    assert r.returncode == 1, r.stderr
    out = json.loads(r.stdout)
    assert_valid_result(out)
    assert (out["procedure"], out["status"], out["verdict"]) == ("stopwatch", "complete", "fail")
    assert out["K_g_mV_per_urad"] == {"X": None}
    assert out["resolved"]["K_g_mV_per_urad"] == {"X": False}
    assert out["simulated"] is True and out["rig"].startswith(RIG)
    assert out["sim_config"] == {"path": str(cfg.resolve()), "sha256": sha}
    assert out["software"]["name"] == "fbs-hil" and out["software"]["commit"] == _commit()
    assert out["time"].endswith("+00:00")
    run = tmp_path / "stopwatch.h5"
    summary = json.loads(run.with_suffix(".json").read_text())
    assert {k: summary[k] for k in ("rig", "simulated", "sim_config", "software", "verdict")} == {
        k: out[k] for k in ("rig", "simulated", "sim_config", "software", "verdict")
    }
    assert any(
        m["name"] == "headline figures measured" and m["passed"] is False
        for m in summary["measurements"]
    )
    report = run.with_suffix(".md").read_text()
    assert f"- rig: `{out['rig']}` (**simulated**)" in report and sha[:16] in report
    assert str(out["software"]["commit"]) in report and "**fail**" in report
    assert not NAN.search(report)
    with RunFile(run) as rf:
        made = rf.meta["provenance"]
    assert made["simulated"] is True and made["rig"] == out["rig"]
    assert made["sim_config"]["sha256"] == sha

    # the text summary (the complete run analysed again): the same verdict, no "± nan"
    text = fbs("run", "stopwatch", "--out", str(tmp_path), "--resume", str(run))
    assert text.returncode == 1, text.stderr
    assert "fbs run stopwatch: fail (complete) on rig " in text.stdout
    assert "(simulated)" in text.stdout
    assert "not resolved" in text.stdout and not NAN.search(text.stdout), text.stdout
    failed = "headline figures measured: 0  FAIL (none of K_g_mV_per_urad"
    assert failed in text.stdout, text.stdout

    # the analysis commands on the sim rig's file: the file's rig, simulated
    capsys.readouterr()
    transfer = [
        "analyze",
        "transfer",
        str(run),
        "--from",
        "torq_x",
        "--to",
        "gyro_x",
        "--seg-s",
        "2",
        "--json",
    ]
    assert main(transfer) == 0
    got = json.loads(capsys.readouterr().out)
    assert_valid_result(got)
    assert (got["analysis"], got["procedure"], got["verdict"]) == ("transfer", "stopwatch", "pass")
    assert got["simulated"] is True and got["sim_config"]["sha256"] == sha

    def interrupted(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr("procedures.analysis.transfer.block_csd", interrupted)
    assert main(transfer) == 2
    got = json.loads(capsys.readouterr().out)
    assert_valid_result(got)
    assert (got["verdict"], got["status"], got["fit"]) == ("aborted", "aborted: interrupted", None)
    monkeypatch.setattr("procedures.analysis.hysteresis.analyze_file", interrupted)
    assert main(["analyze", "hysteresis", str(run), "--axis", "X", "--json"]) == 2
    got = json.loads(capsys.readouterr().out)
    assert_valid_result(got)
    assert (got["analysis"], got["verdict"], got["simulated"]) == ("hysteresis", "aborted", True)
    assert got["To_Nm"] == {"X": None} and got["resolved"]["To_Nm"] == {"X": False}
