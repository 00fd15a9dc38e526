"""A killed worker's scratch directory is removed by the next one made; a live one's is not."""

import signal
import socket
import subprocess
import sys

from fbs.scratch import scratch_dir, sweep

HOLD = """
import sys, time
from pathlib import Path
from fbs.scratch import scratch_dir
with scratch_dir("fbs-t-", Path(sys.argv[1])) as d:
    (d / "record.h5").write_bytes(b"x" * 1000)
    print(d, flush=True)
    time.sleep(600)
"""


def _holder(root):
    p = subprocess.Popen([sys.executable, "-c", HOLD, str(root)], stdout=subprocess.PIPE, text=True)
    return p, p.stdout.readline().strip()


def test_a_killed_process_leaves_its_directory_and_the_next_one_removes_it(tmp_path):
    killed, left = _holder(tmp_path)
    alive, kept = _holder(tmp_path)
    try:
        killed.send_signal(signal.SIGKILL)
        killed.communicate()
        assert (tmp_path / left.split("/")[-1] / "record.h5").exists()  # the kill left it
        others = [
            f"fbs-t-{socket.gethostname()}-notapid-x",  # not ours to judge
            f"fbs-t-another-host-{killed.pid}-x",  # another machine's (or container's) process
            # a host named as this one and "-<the killed pid>" (a dead pid, read wrongly)
            f"fbs-t-{socket.gethostname()}-{killed.pid}-{killed.pid}-x",
        ]
        for name in others:
            (tmp_path / name).mkdir()
        with scratch_dir("fbs-t-", tmp_path) as d:
            names = {p.name for p in tmp_path.iterdir()}
            assert left.split("/")[-1] not in names
            assert {kept.split("/")[-1], *others} <= names
            assert d.is_dir()
        assert not d.exists()  # its own goes when the block ends
    finally:
        for p in (killed, alive):
            if p.poll() is None:
                p.kill()
                p.communicate()
    assert [p.name for p in sweep("fbs-t-", tmp_path)] == [kept.split("/")[-1]]
