"""Who listens on a TCP port of this machine: the process a server of ours should name when its port
is taken ("port 4840 is in use by process 1234: cotwin plant ...").

Linux only, from /proc: /proc/net/tcp and tcp6 list listening sockets with their user and inode, and
/proc/<pid>/fd links a process to the inodes it holds (readable for this user's processes, or all of
them for root). Elsewhere, or when the owner is not visible, the answer says as much.
"""

from __future__ import annotations

import os
import pwd
from dataclasses import dataclass
from pathlib import Path

LISTEN = "0A"


@dataclass(frozen=True)
class Owner:
    uid: int
    pid: int | None = None
    command: str | None = None

    def describe(self) -> str:
        if self.pid is not None:
            return f"process {self.pid}" + (f" ({self.command})" if self.command else "")
        try:
            user = pwd.getpwuid(self.uid).pw_name
        except KeyError:
            user = str(self.uid)
        return f"a process of user {user} (its PID is not visible to this user)"


def _listening_inodes(port: int, proc: Path) -> dict[int, int]:
    """inode -> uid of the sockets listening on `port` (any address)."""
    found = {}
    for table in ("tcp", "tcp6"):
        try:
            lines = (proc / "net" / table).read_text().splitlines()[1:]
        except OSError:
            continue
        for line in lines:
            fields = line.split()
            if len(fields) < 10 or fields[3] != LISTEN:
                continue
            try:
                if int(fields[1].rpartition(":")[2], 16) == port:
                    found[int(fields[9])] = int(fields[7])
            except ValueError:
                continue
    return found


def _command(pid: Path, limit: int = 120) -> str | None:
    try:
        words = (pid / "cmdline").read_bytes().rstrip(b"\0").split(b"\0")
    except OSError:
        return None
    text = " ".join(os.path.basename(w.decode(errors="replace")) if k == 0 else w.decode(errors="replace")
                    for k, w in enumerate(words))
    return text if len(text) <= limit else text[: limit - 3] + "..."


def port_owner(port: int, proc: str | Path = "/proc") -> Owner | None:
    """The process listening on TCP `port`, as far as this user can see; None when nobody listens (or
    the machine has no /proc)."""
    proc = Path(proc)
    inodes = _listening_inodes(port, proc)
    if not inodes:
        return None
    wanted = {f"socket:[{inode}]": inode for inode in inodes}
    try:
        pids = [p for p in proc.iterdir() if p.name.isdigit()]
    except OSError:
        pids = []
    for pid in pids:
        try:
            fds = list((pid / "fd").iterdir())
        except OSError:  # another user's process, or gone
            continue
        for fd in fds:
            try:
                target = os.readlink(fd)
            except OSError:
                continue
            if target in wanted:
                return Owner(inodes[wanted[target]], int(pid.name), _command(pid))
    return Owner(next(iter(inodes.values())))


def in_use_message(host: str, port: int) -> str:
    """Why a server cannot listen on host:port, naming whoever holds it."""
    owner = port_owner(port)
    who = owner.describe() if owner is not None else "another socket (its owner was not found)"
    return f"port {port} on {host} is in use by {who}"
