"""Issue 35 B end to end: two `fbs record` commands on one rig, each in its own process.

The rig is the simulated one served by another process (``python -m simhw.serve``: the ADC on
a pty, the CANopen nodes on ``udp_multicast``, paced to the wall clock), so every host reaches
it as it would hardware: ``serial:///dev/pts/N?can=udp_multicast:GROUP``. The second command
refuses before any byte is sent, names the holder, opens no output; the first records on,
untouched. A second *machine* (its own lock directory) is refused by the bus itself: the first
host's heartbeat is on it.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import h5py
import numpy as np
import pytest

from tests.drivers.multicast import lone_multicast_group
from tests.drivers.waiting import wait_for

pytestmark = pytest.mark.slow

FBS = [sys.executable, "-m", "fbs"]
#: the first recording's length (s; a wall-paced rig): the two refused commands start inside it
FIRST_S = 30


@pytest.fixture
def served_rig():
    with (
        lone_multicast_group() as group,
        subprocess.Popen(
            [sys.executable, "-m", "simhw.serve", "--can", group, "--warm"],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        ) as proc,
    ):
        try:
            assert proc.stdout is not None
            line = proc.stdout.readline().split()
            adc = dict(kv.split("=", 1) for kv in line)["adc"]
            yield f"serial://{adc}?can=udp_multicast:{group}"
        finally:
            if proc.stdin is not None:
                proc.stdin.close()
            proc.wait(timeout=30)


def test_a_second_command_refuses_and_the_first_records_on(served_rig, tmp_path):
    first_out, second_out, third_out = (
        tmp_path / "first.h5",
        tmp_path / "second.h5",
        tmp_path / "third.h5",
    )
    record = ["record", "--rig", served_rig, "--mode", "3", "--rate", "200", "--json"]
    with subprocess.Popen(
        [*FBS, *record, "--duration", str(FIRST_S), "--out", str(first_out)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    ) as first:
        try:
            wait_for(first_out.exists, "the first recording's file", guard_s=120.0)
            other = tmp_path / "other-host-locks"
            other.mkdir()
            # started together, so both are refused inside the first's recording on a loaded box
            # too (each takes seconds to start): the same machine, where the rig claim names the
            # holder, and another machine (a lock directory of its own), which hears the first
            # host's heartbeat on the bus
            second, third = (
                subprocess.Popen(
                    [*FBS, *record, "--duration", "2", "--out", str(path)],
                    stdout=subprocess.PIPE,
                    stderr=subprocess.PIPE,
                    text=True,
                    env=env,
                )
                for path, env in (
                    (second_out, None),
                    (third_out, os.environ | {"FBS_LOCK_DIR": str(other)}),
                )
            )
            with second, third:
                second_err = second.communicate(timeout=120)[1]
                third_err = third.communicate(timeout=120)[1]
            out, err = first.communicate(timeout=120)
        finally:
            if first.poll() is None:
                first.kill()
    assert second.returncode == 2, second_err
    assert f"held by pid {first.pid}" in second_err and "sent nothing" in second_err, second_err
    assert third.returncode == 2, third_err
    assert "another host is driving this bus" in third_err and "sent nothing" in third_err, (
        third_err
    )
    assert not second_out.exists() and not third_out.exists()
    # the first: complete, every sample, no gap, safe at its close
    assert first.returncode == 0, err
    j = json.loads(out)
    assert (j["status"], j["n_samples"], j["lost"], j["gaps"], j["rig_safe_at_close"]) == (
        "complete",
        FIRST_S * 200,
        0,
        [],
        True,
    )
    with h5py.File(first_out, "r") as f:
        assert f.attrs["status"] == "complete"
        assert all(
            len(f["channels"][c]) == FIRST_S * 200 and np.all(np.isfinite(f["channels"][c][:]))
            for c in f["channels"]
        )
        kinds = [k.decode() if isinstance(k, bytes) else k for k in f["events"]["kind"][:]]
        texts = [t.decode() if isinstance(t, bytes) else t for t in f["events"]["text"][:]]
    # nothing happened to the rig while it recorded: no mode change, alarm, error or gap
    assert kinds == ["start"], list(zip(kinds, texts))
