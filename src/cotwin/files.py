"""The files cotwin reads and writes, as a project shipped by someone else may lay them out.

Reading (`read_bytes`, `read_text`): an input is a regular file (not a FIFO that never ends, nor a
device) of at most its kind's cap, checked before it is read (an 8 GB sparse model is refused, not a
MemoryError), and text is UTF-8; a refusal is a CotwinError located at the file (and at the line and
column of a byte that is not UTF-8).

Writing (`write_bytes`, `write_text`, `output`): an output is written whole to a new file made beside
it (O_EXCL: never an existing file, never through a link) and renamed over the target, which replaces
a link rather than following it: a project shipped with `out/figure.png -> /somewhere` gets a new
figure.png, and /somewhere is untouched. An output is never written over a file the same command reads
(`inputs`: the project's models, plan, log, calibration, a history store); the target's folder is
created if missing. A write that fails leaves the previous file as it was.
"""

from __future__ import annotations

import errno
import os
import stat
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Iterable

from .diagnostics import CotwinError, Finding, Location, Severity


def cache_dir() -> Path | None:
    """cotwin's cache (IK solutions, compiled d-models and their extracted FMUs, native loops): $COTWIN_CACHE, "off" for none, else
    $XDG_CACHE_HOME/cotwin or ~/.cache/cotwin."""
    chosen = os.environ.get("COTWIN_CACHE")
    if chosen == "off":
        return None
    if chosen:
        return Path(chosen)
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "cotwin"

MiB = 1 << 20
# What cotwin reads whole, by kind, at most (a published model is under 100 KiB, a plan of hours of
# commands a few MiB; RTDE logs are read as they go, see cotwin.mapping.rtde).
CAPS = {"model": 16 * MiB, "project file": 4 * MiB, "plan": 64 * MiB, "scenario": 64 * MiB,
        "calibration file": 4 * MiB, "world file": 16 * MiB, "multimodel": 16 * MiB, "state": 256 * MiB,
        "mesh": 256 * MiB, "access file": 1 * MiB}
DEFAULT_CAP = 16 * MiB  # any other file cotwin reads whole


def error(path: str | Path, message: str, line: int = 1, column: int = 1) -> CotwinError:
    return CotwinError([Finding(Location(str(path), line, column), Severity.ERROR, message)])


def read_bytes(path: str | Path, what: str, limit: int | None = None) -> bytes:
    """The bytes of the file `what` (capped at CAPS[what], or `limit`), or a located CotwinError."""
    cap = limit if limit is not None else CAPS.get(what, DEFAULT_CAP)
    try:
        with os.fdopen(os.open(path, os.O_RDONLY | os.O_NONBLOCK), "rb") as f:  # a FIFO opens, and is refused
            info = os.fstat(f.fileno())
            if not stat.S_ISREG(info.st_mode):
                raise error(path, f"cannot read {what}: not a regular file")
            if info.st_size > cap:
                raise error(path, f"the {what} is {_size(info.st_size)}, over the {_size(cap)} cotwin reads")
            data = f.read(cap + 1)
    except IsADirectoryError:
        found = sorted(Path(path).glob("*.toml"))[:5] if what == "project file" else []
        hint = f" (it holds {', '.join(p.name for p in found)})" if found else ""
        raise error(path, f"cannot read {what}: it is a folder: name the {what} in it{hint}") from None
    except OSError as err:
        raise error(path, f"cannot read {what}: {err.strerror or err}") from None
    if len(data) > cap:  # grew while being read
        raise error(path, f"the {what} is over the {_size(cap)} cotwin reads")
    return data


def read_text(path: str | Path, what: str, limit: int | None = None) -> str:
    """`read_bytes` decoded as UTF-8 (a byte order mark dropped); a byte that is not is located."""
    raw = read_bytes(path, what, limit)
    try:
        return raw.decode("utf-8").removeprefix("\ufeff")
    except UnicodeDecodeError as err:
        line = raw.count(b"\n", 0, err.start) + 1
        column = err.start - (raw.rfind(b"\n", 0, err.start) + 1) + 1
        raise error(path, f"the {what} is not UTF-8 text (byte 0x{raw[err.start]:02x})", line, column) from None


def _size(n: int) -> str:
    return f"{n / MiB:.0f} MiB" if n >= MiB else f"{n} bytes"


# ---- outputs ------------------------------------------------------------------------------------

def _umask() -> int:
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    return 0o022


def check_outputs(outputs: Iterable[str | Path], inputs: Iterable[str | Path | None], hint: str = "-o") -> None:
    """CotwinError if an output would replace one of the inputs (the same path, or the same file by another
    name: a hard link, a linked folder); checked before anything runs."""
    known = []
    for source in inputs:
        if source is None:
            continue
        try:
            info = os.stat(source)
            known.append((Path(source), os.path.abspath(source), (info.st_dev, info.st_ino)))
        except OSError:
            known.append((Path(source), os.path.abspath(source), None))
    clashes = []
    for target in outputs:
        absolute = os.path.abspath(target)
        try:
            info = os.lstat(target)
            identity = None if stat.S_ISLNK(info.st_mode) else (info.st_dev, info.st_ino)  # a link is replaced
        except OSError:
            identity = None
        clashes += [(target, source) for source, spelled, inode in known
                    if absolute == spelled or (identity is not None and identity == inode)]
    if clashes:  # an input named twice (the project's plan given as --plan too) is said once
        clashes = list({(os.path.abspath(t), os.path.abspath(s)): (t, s) for t, s in clashes}.values())
        raise CotwinError([Finding(Location(str(target), 0, 0), Severity.ERROR,
                                   f"the output would replace {source}, which this command reads: choose another "
                                   f"output ({hint})") for target, source in clashes])


def special_file(path: str | Path) -> str | None:
    """What `path` is when it is there as neither a file, a folder nor a link (a device, a FIFO, a socket), else
    None: an output renamed over it replaces it (`-o /dev/null` run as root left a CSV where the device was)."""
    try:
        mode = os.lstat(path).st_mode
    except OSError:
        return None
    kinds = ((stat.S_ISCHR, "a device"), (stat.S_ISBLK, "a device"), (stat.S_ISFIFO, "a FIFO"), (stat.S_ISSOCK, "a socket"))
    return next((kind for test, kind in kinds if test(mode)), None)


def refuse_special(path: str | Path) -> None:
    """CotwinError if `path` is a device, a FIFO or a socket (`special_file`): cotwin writes a file in its place."""
    kind = special_file(path)
    if kind is not None:
        raise error(path, f"is {kind}, not a file: cotwin writes its output as a new file in its place; name a file")


class Reserved:
    """An output made now and put in place later (see module doc): the new file beside `path`, open, so that a
    place it cannot be written is found before the work whose result it holds (a run's state: before its
    first step, not after its last), and the work's end only writes and renames. `discard` removes it."""

    def __init__(self, path: str | Path, inputs: Iterable[str | Path | None] = (), mode: int | None = None):
        self.path = path = Path(path)
        check_outputs([path], inputs)
        refuse_special(path)
        if path.is_dir():  # else the error would name the temporary file beside it
            raise CotwinError([Finding(Location(str(path), 0, 0), Severity.ERROR, "is a folder: cannot write a file there")])
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            # a name of 255 bytes has a temporary one too: its first 200 bytes as the file system spells them (a name
            # that is not UTF-8 has surrogates, which a strict encode refused; a cut character stays bytes)
            stem = os.fsdecode(os.fsencode(path.name)[:200])
            self.fd, self.part = tempfile.mkstemp(prefix=f".{stem}.", suffix=".part", dir=path.parent)  # O_EXCL, mode 600
        except OSError as err:  # named by the file asked for, not the temporary one beside it
            raise CotwinError([Finding(Location(str(path), 0, 0), Severity.ERROR,
                                       f"cannot write here: {err.strerror or err}")]) from None
        try:
            os.fchmod(self.fd, mode if mode is not None else 0o666 & ~_umask())
        except BaseException:
            self.discard()
            raise

    def open(self, text: bool = False, newline: str | None = None):
        """The new file, open for writing (binary, or text with `text`); closing it closes the reservation's."""
        return os.fdopen(self.fd, "w" if text else "wb", **({"encoding": "utf-8", "newline": newline} if text else {}))

    def put(self, data: bytes) -> Path:
        """`data` written to the new file, which then replaces `path`; removed instead if that fails."""
        try:
            with self.open() as f:
                self.fd = None
                f.write(data)
            os.replace(self.part, self.path)
        except BaseException:
            self.discard()
            raise
        self.part = None
        return self.path

    def discard(self) -> None:
        """The new file removed, `path` left as it was (idempotent)."""
        if self.fd is not None:
            try:
                os.close(self.fd)
            except OSError:
                pass
            self.fd = None
        if self.part is not None:
            try:
                os.unlink(self.part)
            except OSError:
                pass
            self.part = None


@contextmanager
def output(path: str | Path, inputs: Iterable[str | Path | None] = (), mode: int | None = None, text: bool = False,
           newline: str | None = None):
    """A file to write `path` through (see module doc): yields an open file (binary, or text with
    `text`), renamed over `path` when the block ends without an error, removed otherwise."""
    reserved = Reserved(path, inputs, mode)
    try:
        with reserved.open(text, newline) as f:
            reserved.fd = None
            yield f
        os.replace(reserved.part, reserved.path)
        reserved.part = None
    finally:
        reserved.discard()


def write_bytes(path: str | Path, data: bytes, inputs: Iterable[str | Path | None] = (), mode: int | None = None) -> Path:
    with output(path, inputs, mode) as f:
        f.write(data)
    return Path(path)


def write_text(path: str | Path, text: str, inputs: Iterable[str | Path | None] = (), mode: int | None = None) -> Path:
    with output(path, inputs, mode, text=True, newline="") as f:
        f.write(text)
    return Path(path)


def open_exclusive(path: str | Path) -> int:
    """A descriptor on the regular file `path` (created if missing) that cotwin owns and rewrites in place
    (a lock file, a result being written): never through a link (one found there is removed, it cannot be
    ours) and never a file with another name too (a hard link planted there would be truncated with it)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    for _ in range(2):
        try:
            fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW, 0o666 & ~_umask())
        except OSError as err:
            if err.errno == errno.ELOOP:  # a symbolic link
                os.unlink(path)
                continue
            raise
        info = os.fstat(fd)
        if stat.S_ISREG(info.st_mode) and info.st_nlink == 1:
            return fd
        os.close(fd)
        raise error(path, "not a file cotwin made: " + ("it has other names (hard links)" if stat.S_ISREG(info.st_mode)
                                                      else "not a regular file") + "; remove it")
    raise error(path, "a link keeps reappearing here; remove it")
