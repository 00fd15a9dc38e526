"""What the ``fbs`` command tests share: how they start the command, the rig they run on and
the shortest stopwatch the command runs (one way to write each, rather than one per file)."""

from __future__ import annotations

import sys

#: the command as a user's shell starts it, in the suite's interpreter
FBS = [sys.executable, "-m", "fbs.cli"]
#: the sim rig the command tests run procedures on: warm (wheels at speed), seeded
RIG = "sim?warm=1&seed=5&watchdog=5"
#: stopwatch parameters for one channel, one repetition, short holds: seconds on the sim rig
#: (K_g then not resolved: one repetition has no spread)
SHORT_STOPWATCH = [
    "--param",
    'channels=["X"]',
    "--param",
    "repetitions=1",
    "--param",
    "min_caged_s=10",
    "--param",
    "hold_s=5",
    "--param",
    "null_s=5",
    "--param",
    "restore_s=10",
]
