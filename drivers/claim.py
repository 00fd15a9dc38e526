"""One host per rig: an exclusive claim taken before any byte goes to a device.

A second ``fbs`` command on a rig that is recording would otherwise do its whole connect -
NMT commands, heartbeat settings, the ADC's STOP - and end the first one's stream. The claim
has three parts, each checked before this host sends anything:

* a lock file per device the rig URL names (the ADC port by its real path, the CAN channel),
  held with ``flock`` for the session; the file says who holds it (pid, command, since), so a
  refusal can name the holder. The kernel drops the lock when its holder dies, however it
  dies: a stale file never blocks;
* the ADC port opened exclusively (``serial.Serial(exclusive=True)``, ``drivers.serial_adc``);
* a host heartbeat (``0x77F``) already on the CAN bus means a host this machine's locks cannot
  see (another PC on the bus): refused (``drivers.can_link``).

The locks live in ``$FBS_LOCK_DIR``, else ``$XDG_RUNTIME_DIR/fbs-hil``, else
``<tempdir>/fbs-hil-<uid>``.
"""

from __future__ import annotations

import fcntl
import json
import os
import re
import sys
import tempfile
import time
from pathlib import Path

from drivers.errors import RigBusy

#: environment variable naming the lock directory (tests give each their own)
LOCK_DIR_ENV = "FBS_LOCK_DIR"


def lock_dir() -> Path:
    if os.environ.get(LOCK_DIR_ENV):
        return Path(os.environ[LOCK_DIR_ENV])
    if os.environ.get("XDG_RUNTIME_DIR"):
        return Path(os.environ["XDG_RUNTIME_DIR"]) / "fbs-hil"
    return Path(tempfile.gettempdir()) / f"fbs-hil-{os.getuid()}"


def resource_key(kind: str, name: str) -> str:
    """A lock file name for a device: an ADC port by its real path (two names of one tty are one
    port), a CAN channel by its interface and channel."""
    if kind == "adc":
        name = os.path.realpath(name)
    return f"{kind}-" + re.sub(r"[^A-Za-z0-9._-]+", "_", name).strip("_")


class RigClaim:
    """Exclusive locks on the devices ``resources`` ((kind, name) pairs) for this process.
    ``RigBusy`` names the holder of the first one held elsewhere; nothing is left locked then."""

    def __init__(
        self, url: str, resources: list[tuple[str, str]], *, directory: Path | None = None
    ) -> None:
        self.url = url
        self.directory = directory or lock_dir()
        self._held: list[tuple[Path, int]] = []
        try:
            self.directory.mkdir(parents=True, exist_ok=True, mode=0o700)
            for kind, name in resources:
                self._take(self.directory / (resource_key(kind, name) + ".lock"), f"{kind} {name}")
        except BaseException:
            self.release()
            raise

    def _take(self, path: Path, what: str) -> None:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o600)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = _describe(path)
            os.close(fd)
            raise RigBusy(
                f"rig {self.url}: its {what} is held by {holder}; this command sent nothing to the "
                f"rig. Wait for that command to end (or stop it), then try again"
            ) from None
        except OSError:
            os.close(fd)
            raise
        os.ftruncate(fd, 0)
        os.write(
            fd,
            json.dumps(
                {
                    "pid": os.getpid(),
                    "command": " ".join(_command()),
                    "url": self.url,
                    "since": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
                }
            ).encode(),
        )
        self._held.append((path, fd))

    def release(self) -> None:
        while self._held:
            path, fd = self._held.pop()
            try:
                os.ftruncate(fd, 0)  # the next holder writes its own; a reader sees no stale holder
            finally:
                os.close(fd)

    def __enter__(self) -> RigClaim:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()


def _command() -> list[str]:
    argv = list(sys.argv)
    if argv and argv[0].endswith(("/fbs", "fbs/__main__.py", "-m")):
        argv[0] = "fbs"
    return argv


def _describe(path: Path) -> str:
    """'pid 1234 (fbs record --mode 3 ...) since 2026-11-27T23:30:00+0000', or what is known."""
    try:
        info = json.loads(path.read_text() or "{}")
    except (OSError, ValueError):
        info = {}
    if not info:
        return "another process (it has not yet said which)"
    return f"pid {info.get('pid', '?')} ({info.get('command', '?')}) since {info.get('since', '?')}"
