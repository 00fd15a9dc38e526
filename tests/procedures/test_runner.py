"""The procedure runner on the loopback rig: steps and their events, measurements and the
verdict, progress, every abort path (Ctrl-C, an exception, a device fault, the operator's
abort) leaving the rig safe and the file "aborted: <why>", and resume."""

from __future__ import annotations

import json
import math
import os
import re
import signal
import threading
import time
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import pytest

from daq.reader import RunFile
from drivers.rig import open_rig
from fbs.signals import aborting_on_signals
from procedures.calibrations import catalogue
from procedures.held_signals import signals_held
from procedures.procedure import Analysis, Figure, Measurement, Procedure, ProcedureError, Step
from procedures.resume import load_resume, next_free
from procedures.runner import run_procedure
from procedures.stepresult import StepResult

pytestmark = pytest.mark.slow


@dataclass
class ToyParams:
    n_data_steps: int = 3
    step_s: float = 2.0
    bias_V: float = 0.3
    limit_lo: float = -10.0


@dataclass(frozen=True)
class SetUp(StepResult):
    ok: bool


@dataclass(frozen=True)
class DataMean(StepResult):
    digits: ClassVar[int] = 17  # every double exactly: the tests compare the means as samples

    i: int
    mean: float


class Toy(Procedure):
    """Biases torquer X, records, and measures the mean torquer output (a real measurement)."""

    name = "toy"
    title = "toy procedure for the runner tests"
    json_keys = ("mean_V", "file")
    Params = ToyParams
    rate_hz = 50.0

    def __init__(self, params=None, *, fail_in: str | None = None, **kw) -> None:
        super().__init__(params, **kw)
        self.fail_in = fail_in
        self.setup_runs = 0

    def channels(self):
        return ("torq_x", "gyro_x")

    def plan(self):
        return [
            Step("setup", self.setup, expected_s=1.0, setup=True, result=SetUp),
            *(
                Step(
                    f"data {i}",
                    lambda c, i=i: self.data(c, i),
                    expected_s=self.params.step_s,
                    result=DataMean,
                )
                for i in range(self.params.n_data_steps)
            ),
        ]

    def setup(self, ctx):
        self.setup_runs += 1
        ctx.rig.set_caging_inhibit("X", True)
        ctx.rig.set_torquer_bias_V("X", self.params.bias_V)
        ctx.acquire(1.0, keep=False)
        return SetUp(ok=True)

    def data(self, ctx, i):
        if self.fail_in == f"data {i}":
            raise ProcedureError(f"toy failure in data {i}")
        x = ctx.acquire(self.params.step_s)
        return DataMean(i=i, mean=float(np.nanmean(x[:, 0])))

    def analyze(self, ctx):
        # the samples the runner says the data steps recorded, read back from their files
        self.analysed = {}
        for name, span in ctx.spans.items():
            with RunFile(span.file) as rf:
                self.analysed[name] = (span, rf.read(["torq_x"], span.start, span.stop)[0])
        means = [ctx.result(f"data {i}", DataMean).mean for i in range(self.params.n_data_steps)]
        m = float(np.mean(means))
        return Analysis(
            {"mean_V": m}, [Measurement("mean torquer X", m, "V", lo=self.params.limit_lo, hi=10.0)]
        )


@pytest.fixture
def rig():
    with open_rig("sim?warm=1&seed=1&watchdog=5") as r:
        yield r


def _mode(rig) -> int:
    return rig.relays.status().mode


def test_steps_events_measurements_and_verdict(rig, tmp_path):
    seen = []
    s = run_procedure(Toy(), rig, tmp_path, progress=seen.append)
    assert s.verdict == "pass" and s.exit_code == 0 and s.status == "complete"
    assert s.steps_done == ["setup", "data 0", "data 1", "data 2"]
    # a bias of 0.3 V through the open loop: the torquer reads a real, non-zero output
    assert abs(s.values["mean_V"]) > 0.1
    with RunFile(s.file) as rf:
        assert rf.attrs["procedure"] == "toy" and rf.status == "complete"
        kinds = [e.kind for e in rf.events]
        done = [json.loads(e.text) for e in rf.events if e.kind == "step-done"]
        assert rf.meta["procedure"]["params"]["n_data_steps"] == 3
        assert "calibration" in rf.meta
    assert kinds.count("step") == 4 and [d["step"] for d in done] == s.steps_done
    assert done[1]["result"]["i"] == 0
    # progress: fractions rise with step names, then the analysis and report, 1 when done
    assert seen and seen[-1].fraction == pytest.approx(1.0) and seen[-1].phase == "done"
    assert [p.step for p in seen if p.phase == "steps"][-1] == "data 2"
    assert [p.phase for p in seen][-3:] == ["analysing", "writing report", "done"]
    assert all(b.fraction >= a.fraction for a, b in zip(seen, seen[1:]))
    # report and JSON summary beside the file
    assert s.report.exists() and "mean torquer X" in s.report.read_text()
    assert json.loads(s.file.with_suffix(".json").read_text())["verdict"] == "pass"
    assert s.json_values(Toy.json_keys) == {"mean_V": s.values["mean_V"], "file": str(s.file)}


class OpenEnded(Toy):
    """A toy whose analysis gives an interval open above and a figure it cannot define."""

    def analyze(self, ctx):
        a = super().analyze(ctx)
        a.values |= {"mean_V_ci95": {"X": [0.0, math.inf]}, "spread_V": math.nan}
        return a


def test_the_summary_beside_the_run_is_strict_json_with_open_ends_null(rig, tmp_path):
    """A summary file is read by tools other than Python's json (jq, a browser): no Infinity
    or NaN in it. An interval's open end is null, as ``--json`` prints it."""
    s = run_procedure(OpenEnded(), rig, tmp_path)
    text = s.file.with_suffix(".json").read_text()

    def refuse(token: str) -> None:
        raise AssertionError(f"{token} in the summary: not JSON")

    values = json.loads(text, parse_constant=refuse)["values"]
    assert values["mean_V_ci95"] == {"X": [0.0, None]} and values["spread_V"] is None
    assert s.values["mean_V_ci95"]["X"][1] == math.inf  # the run's own values keep it


def test_limits_failed_gives_exit_code_1(rig, tmp_path):
    s = run_procedure(Toy(ToyParams(limit_lo=9.0)), rig, tmp_path)
    assert s.verdict == "fail" and s.exit_code == 1
    assert s.measurements[0].passed is False and "**FAIL**" in s.report.read_text()


def _assert_aborted_and_safe(rig, s, why: str) -> None:
    assert s.verdict == "aborted" and s.exit_code == 2
    assert s.status.startswith("aborted: ") and why in s.status
    assert _mode(rig) == 1 and rig.is_safe()
    assert rig.torquers.bias_V("X") == 0.0 and not rig.caging.inhibited("X")
    with RunFile(s.file) as rf:
        assert rf.status == s.status
        assert any(e.kind == "safe" for e in rf.events)
    assert "Steps not done" in s.report.read_text()


@dataclass(frozen=True)
class Bloated(StepResult):
    text: str


class _Oversize(Toy):
    """A Toy whose second data step returns a result too large for its event."""

    def plan(self):
        steps = super().plan()
        steps[2] = Step("data 1", self.bloated, expected_s=self.params.step_s, result=Bloated)
        return steps

    def bloated(self, ctx):
        ctx.acquire(self.params.step_s, keep=False)
        return Bloated(text="x" * 2000)


def test_an_oversize_step_result_aborts_to_the_safe_state_naming_step_size_and_limit(rig, tmp_path):
    """Issue 40 item 2: a result that would not fit its step-done event (TEXT_BYTES) is refused
    where it is written, naming the procedure, the step, its size and the limit; the run goes
    through the abort teardown (rig safe, file "aborted: StepResultTooLarge: ...")."""
    s = run_procedure(_Oversize(), rig, tmp_path)
    _assert_aborted_and_safe(rig, s, "StepResultTooLarge")
    m = re.search(r"toy: step 'data 1': its result is (\d+) bytes of JSON.*\(1024\)", s.error)
    assert m and 2000 < int(m.group(1)) < 2200, s.error
    assert s.steps_done == ["setup", "data 0"]


def test_ctrl_c_aborts_to_the_safe_state(rig, tmp_path):
    calls = []

    def ctrl_c(
        p,
    ):  # the listener runs on the procedure's thread: a KeyboardInterrupt as from SIGINT
        calls.append(p)
        if p.step == "data 1":
            raise KeyboardInterrupt

    s = run_procedure(Toy(), rig, tmp_path, progress=ctrl_c)
    _assert_aborted_and_safe(rig, s, "interrupted")
    assert s.steps_done == ["setup", "data 0"] and s.error == "interrupted (Ctrl-C)"


def test_an_exception_in_a_step_aborts_with_its_reason(rig, tmp_path):
    s = run_procedure(Toy(fail_in="data 2"), rig, tmp_path)
    _assert_aborted_and_safe(rig, s, "toy failure in data 2")
    assert s.steps_done == ["setup", "data 0", "data 1"]


def test_the_runner_goes_safe_through_the_drivers_one_guard(rig, tmp_path, go_safe_calls):
    """The runner owns the teardown, through ``drivers.safety`` (once per abort); the recorder
    only closes the file, after the safe state is in it."""
    s = run_procedure(Toy(fail_in="data 1"), rig, tmp_path)
    _assert_aborted_and_safe(rig, s, "toy failure in data 1")
    assert go_safe_calls == ["toy aborted (ProcedureError: toy failure in data 1)"]
    ok = run_procedure(Toy(ToyParams(n_data_steps=1)), rig, tmp_path)
    assert ok.verdict == "pass" and len(go_safe_calls) == 1  # a clean run does not go safe


def test_a_device_fault_aborts(rig, tmp_path):
    def fault(p):
        if p.step == "data 1":
            rig.emulator.inject("adc", "disconnect")

    s = run_procedure(Toy(ToyParams(step_s=4.0)), rig, tmp_path, progress=fault)
    assert s.verdict == "aborted" and s.status.startswith("aborted: ")
    assert "DeviceLost" in s.status and "ADC" in s.status
    # every later driver call raises the latched fault; the read-back of the safe state does not
    assert rig.is_safe() and rig.emulator.nodes.nodes["relay"].mode == 1


def test_operator_abort_event(rig, tmp_path):
    stop = threading.Event()
    s = run_procedure(
        Toy(),
        rig,
        tmp_path,
        abort=stop,
        progress=lambda p: stop.set() if p.step == "data 0" else None,
    )
    _assert_aborted_and_safe(rig, s, "aborted by the operator")


def test_resume_takes_over_done_data_steps_and_reruns_setup(rig, tmp_path):
    first = run_procedure(Toy(fail_in="data 2"), rig, tmp_path)
    assert first.verdict == "aborted"
    resumed = load_resume(first.file, Toy)
    assert set(resumed.results) == {"setup", "data 0", "data 1"}
    toy = Toy(Toy.params_from(resumed.params))
    s = run_procedure(toy, rig, tmp_path, resume=resumed)
    assert s.verdict == "pass" and s.file != first.file and s.file.name == "toy-2.h5"
    assert s.steps_resumed == ["data 0", "data 1"] and toy.setup_runs == 1
    with RunFile(s.file) as rf:
        assert rf.meta["procedure"]["resumed_from"] == str(first.file)
        taken = [
            json.loads(e.text) for e in rf.events if e.kind == "step-done" and "resumed" in e.text
        ]
    assert [t["step"] for t in taken] == ["data 0", "data 1"]
    assert DataMean.from_json(taken[0]["result"]) == resumed.results["data 0"]
    assert isinstance(resumed.results["setup"], SetUp)
    # the aborted file is kept as it was
    with RunFile(first.file) as rf:
        assert rf.status.startswith("aborted: ")


def test_the_runner_hands_analyze_the_samples_each_data_step_recorded_across_a_resume(
    rig, tmp_path
):
    """Provenance is the runner's: a resumed run's analysis reads data 0-1 from the aborted
    file and data 2 from its own, exactly the samples each step took (their means are the
    step results), never the setup step's; the summary and the step-done events carry them."""
    first = run_procedure(Toy(fail_in="data 2"), rig, tmp_path)
    assert set(first.spans) == {"data 0", "data 1"}
    toy = Toy()
    s = run_procedure(toy, rig, tmp_path, resume=load_resume(first.file, Toy))
    assert s.verdict == "pass"
    assert set(toy.analysed) == {"data 0", "data 1", "data 2"}
    n = int(round(toy.params.step_s * toy.rate_hz))
    for name, (span, x) in toy.analysed.items():
        here = first if name in ("data 0", "data 1") else s
        assert span.file == here.file.resolve() and span.samples == n == len(x)
        assert span == here.spans[name]
        assert float(np.nanmean(x)) == pytest.approx(ctx_mean(here, name), abs=1e-12)
    # data 0 starts where the setup step ended (its 1 s is not analysed); data 1 follows on
    a, b = toy.analysed["data 0"][0], toy.analysed["data 1"][0]
    assert a.start == int(round(1.0 * toy.rate_hz)) and b.start == a.stop
    summary = json.loads(s.file.with_suffix(".json").read_text())
    assert summary["spans"]["data 0"]["file"] == str(first.file.resolve())
    with RunFile(s.file) as rf:
        done = {
            d["step"]: d for d in (json.loads(e.text) for e in rf.events if e.kind == "step-done")
        }
    assert (
        done["data 2"]["span"]["start"] == s.spans["data 2"].start and "span" not in done["setup"]
    )


def ctx_mean(summary, step: str) -> float:
    """The mean a data step measured, from the step-done event of the file it ran in."""
    with RunFile(summary.file) as rf:
        for e in rf.events:
            d = json.loads(e.text) if e.kind == "step-done" else None
            if d and d["step"] == step and "resumed" not in d:
                return d["result"]["mean"]
    raise AssertionError(f"no step-done for {step} in {summary.file}")


def test_resume_refuses_complete_or_foreign_runs(rig, tmp_path):
    s = run_procedure(Toy(ToyParams(n_data_steps=1)), rig, tmp_path)
    with pytest.raises(ProcedureError, match="complete; nothing to resume"):
        load_resume(s.file, Toy)
    with pytest.raises(ProcedureError, match="is a 'toy' run, not 'earth-rate'"):
        load_resume(s.file, catalogue()["earth-rate"])


class _Interrupted(Toy):
    """A Toy interrupted after its acquisition: in ``analyze``, or in its report, where a plot
    is drawn (a ``KeyboardInterrupt``, as ``fbs.signals`` makes of SIGINT/SIGTERM/SIGHUP)."""

    def __init__(self, stage: str) -> None:
        super().__init__()
        self.stage, self.summary_seen = stage, None

    def analyze(self, ctx):
        if self.stage == "analysis":
            raise KeyboardInterrupt
        a = super().analyze(ctx)
        a.figures.append(Figure("plot", "a plot", self._draw))
        return a

    def _draw(self, png):
        self.summary_seen = png.with_name("toy.json").exists()
        raise KeyboardInterrupt


@pytest.mark.parametrize("stage", ["analysis", "report"])
def test_a_signal_after_the_acquisition_leaves_a_true_summary_and_resume_analyses_again(
    rig, tmp_path, stage
):
    """Issue 36 item 11: SIGHUP while the report was written left exit 2, a summary saying
    pass/complete and no report, and ``--resume`` refused the complete file. The summary is
    now written after the report and says the run was interrupted; a resume of the complete
    file analyses it again, moving nothing, and writes the report and a true summary."""
    toy, md = _Interrupted(stage), tmp_path / "toy.md"
    try:
        s = run_procedure(toy, rig, tmp_path)
    except KeyboardInterrupt:  # would end the session: a failure of this test instead
        summary = (tmp_path / "toy.json").read_text()
        pytest.fail(f"the interruption escaped the runner; its summary: {summary}")
    assert s.verdict == "aborted" and s.exit_code == 2 and s.status == "complete"  # the file is
    summary = json.loads((tmp_path / "toy.json").read_text())
    assert summary["verdict"] == "aborted" and f"--resume {s.file}" in summary["error"]
    if stage == "report":
        assert toy.summary_seen is False  # the summary is written after it
        assert "interrupted while the report was written" in summary["error"]
        assert "no report" in summary["error"]
        assert s.report is None and summary["report"] is None and not md.exists()
    else:  # a report of the aborted analysis, as of any aborted run
        assert "interrupted during the analysis" in summary["error"]
        assert summary["report"] == str(md) and "**aborted**" in md.read_text()
    # the console's default: a complete run is refused
    with pytest.raises(ProcedureError, match="complete; nothing to resume"):
        load_resume(s.file, Toy)
    again = load_resume(s.file, Toy, complete_ok=True)
    assert again.complete and again.taken_over == []
    toy = Toy(Toy.params_from(again.params), prior=again.prior)
    s2 = run_procedure(toy, rig, tmp_path / "elsewhere", resume=again)
    assert s2.verdict == "pass" and s2.exit_code == 0 and s2.error is None
    assert s2.status == "complete" and s2.file == s.file and s2.report == md
    assert "mean torquer X" in md.read_text()
    # the rig not moved: no setup step ran; the analysis read the file's three data steps
    assert toy.setup_runs == 0 and set(toy.analysed) == {"data 0", "data 1", "data 2"}
    assert s2.steps_done == s2.steps_planned == ["setup", "data 0", "data 1", "data 2"]
    summary = json.loads((tmp_path / "toy.json").read_text())
    assert summary["verdict"] == "pass" and summary["report"] == str(tmp_path / "toy.md")
    assert [p.name for p in tmp_path.glob("*.h5")] == ["toy.h5"]
    assert not (tmp_path / "elsewhere").exists()  # beside the run file, whatever out_dir
    with RunFile(s.file) as rf:
        assert rf.status == "complete"


def test_a_signal_while_the_summary_is_written_acts_after_it():
    """The summary is written whole: SIGHUP (here sent to itself) is held until it is."""
    reached = False
    with aborting_on_signals(), pytest.raises(KeyboardInterrupt):
        with signals_held():
            os.kill(os.getpid(), signal.SIGHUP)
            time.sleep(0.05)  # an unheld signal raises here
            reached = True
        time.sleep(1.0)  # a hang guard: it has been raised before
    assert reached


def test_next_free_never_reuses_a_name(tmp_path):
    assert next_free(tmp_path, "x").name == "x.h5"
    (tmp_path / "x.h5").write_bytes(b"")
    (tmp_path / "x-2.json").write_text("{}")
    assert next_free(tmp_path, "x").name == "x-3.h5"


def test_catalogue_finds_every_procedure_and_keys_are_design_section_7():
    design = {
        "earth-rate": ("K_TO_urad_per_s_per_V", "drift_urad_per_s", "file"),
        "stopwatch": ("K_g_mV_per_urad", "file"),
        "hysteresis": ("To_Nm", "eta_per_Nm", "stiffness_Nm_per_rad", "file"),
        # and the platform rms net of the baseline's pickoff noise: docs/procedures/survey.md
        "survey": ("platform_rms_urad", "platform_rms_baseline_net_urad", "dip_hz", "file"),
        "drift": ("bias_instability_urad_per_s", "arw_urad_per_sqrt_s", "file"),
        # not in DESIGN.md section 7 (which names `fbs run excitation` but not its keys):
        # docs/procedures/excitation.md
        "excitation": ("network", "inertia_kg_m2", "damping_Nms", "stiffness_Nm_per_rad", "file"),
        # DESIGN.md section 7 names `fbs run baseline`; its keys: docs/procedures/baseline.md
        "baseline": (
            "nea_urad",
            "white_urad_per_rtHz",
            "flicker_corner_hz",
            "pickoff_rms_urad",
            "pickoff_lines_hz",
            "file",
        ),
    }
    procs = catalogue()
    assert set(procs) == set(design)
    for name, keys in design.items():
        # DESIGN.md's keys, in its order; a procedure may report more figures (earth-rate's g-drifts)
        assert [k for k in procs[name].json_keys if k in keys] == list(keys)


def test_a_step_span_beside_its_run_file_is_named_by_its_name_and_read_back_whole(tmp_path):
    """A step's event holds its span; with the absolute path in it, a run directory deep enough
    (CI's temporary paths) pushed the event past its 1024 bytes and aborted the run."""
    from procedures.procedure import Span

    deep = tmp_path.joinpath(*["a-rather-long-directory-name"] * 30)
    deep.mkdir(parents=True)
    run, data = deep / "stopwatch-2.h5", deep / "stopwatch.h5"
    data.touch()
    span = Span(data.resolve(), 10, 2010, 1000.0)
    text = span.to_json(recorded_in=run)
    assert text["file"] == "stopwatch.h5"
    assert Span.from_json(text, run) == span
    elsewhere = Span(tmp_path.resolve() / "other.h5", 0, 5, 1000.0)
    assert elsewhere.to_json(recorded_in=run)["file"] == str(tmp_path.resolve() / "other.h5")
