"""What is in cotwin's cache (cotwin.files.cache_dir), how it is bounded, and how an entry in use is kept.

The cache holds four kinds of entries (KINDS), each in a folder of its own: native loops compiled by
cotwin.cbuild (`native/STEM-DIGEST.so`), compiled d-model binaries (`binaries/DIGEST.so`, copied out at each
build), extracted cotwin-built FMUs (`fmu/DIGEST/`, loaded in place) and IK solutions (`ik/DIGEST.json`, a
`.lock` beside each). Anything else found there was not written by cotwin and is never removed.

Bound: every time cotwin writes a new entry of a rebuildable kind (`bound`), and the cache is then over its
cap (COTWIN_CACHE_MAX_MB, default 512), the least recently used entries of the rebuildable kinds (native,
binaries, fmu: built again when next needed) are removed, oldest first, until it is under. IK solutions
(small, and costly to find again) are counted but never evicted.

In use: an entry loaded in place (a native loop, an extracted FMU) is `hold`-ed by the process using it: a
shared flock on the file or folder, for as long as it is loaded, which also sets its mtime to now (the
"recently used" of LRU; atime is not kept on most mounts). Removing an entry takes an exclusive flock without
waiting, so an entry held by any running process (this one or another) is skipped, and a process asking for
an entry being removed at that moment is refused the hold and builds it again. A lock rather than age alone
because a twin runs for days on an FMU it extracted once; entries younger than a minute (FRESH) are skipped
too, for a process between writing an entry and holding it, and for cotwin versions that did not hold.

The cache is an optimisation, never a failure: nothing here raises on a cache that is read-only, full, a file,
or removed while it is read; `bound` and `hold` then do nothing (or return None).
"""

from __future__ import annotations

import errno
import fcntl
import os
import re
import shutil
import stat
import time
from dataclasses import dataclass, field
from pathlib import Path

from .diagnostics import CotwinError, Finding, Location, Severity
from .files import MiB, cache_dir

DEFAULT_CAP_MB = 512
FRESH = 60.0  # s: an entry or a partial file younger than this is never evicted


@dataclass(frozen=True)
class Kind:
    folder: str
    what: str  # "3 <what>"
    entry: re.Pattern  # an entry's name
    partial: re.Pattern  # a file or folder cotwin makes while writing an entry (left over by a killed process)
    folders: bool  # entries are folders
    rebuildable: bool  # evicted by the bound


_HEX = "[0-9a-f]"
KINDS = (
    Kind("native", "compiled native loops", re.compile(rf"[A-Za-z0-9_]+-{_HEX}{{20}}\.so"),
         re.compile(rf"\.[A-Za-z0-9_]+-{_HEX}{{20}}\.so\..+\.part"), False, True),
    Kind("binaries", "compiled d-model binaries", re.compile(rf"{_HEX}{{64}}\.so"),
         re.compile(rf"{_HEX}{{64}}\.so\.{_HEX}{{32}}\.part"), False, True),
    Kind("fmu", "extracted FMUs", re.compile(rf"{_HEX}{{24}}"), re.compile(rf"\.{_HEX}{{24}}\.\d+\.\d+"), True, True),
    Kind("ik", "IK solution files", re.compile(rf"{_HEX}{{32}}\.json(\.lock)?"),
         re.compile(rf"\.{_HEX}{{32}}\.json\..+\.part"), False, False),
)
BY_FOLDER = {k.folder: k for k in KINDS}


@dataclass
class Entry:
    kind: Kind
    path: Path
    size: int  # bytes (of every file in a folder)
    used: float  # mtime: when it was written or last held
    partial: bool = False


@dataclass
class Contents:
    """A cache folder's entries (cotwin's) and what else is in it (`foreign`, never removed)."""

    root: Path
    entries: list[Entry] = field(default_factory=list)
    foreign: list[Path] = field(default_factory=list)

    @property
    def size(self) -> int:
        return sum(e.size for e in self.entries)

    def of(self, kind: Kind) -> list[Entry]:
        return [e for e in self.entries if e.kind is kind]


def _folder_size(path: Path) -> int:
    total = 0
    for base, dirs, files in os.walk(path, onerror=lambda err: None):
        for name in files:
            try:
                total += os.lstat(os.path.join(base, name)).st_size
            except OSError:  # removed meanwhile
                pass
    return total


def contents(root: Path) -> Contents:
    """What is in the cache folder `root` (nothing when it is missing; an entry removed while read is left out).
    OSError when `root` cannot be listed (not a folder, no permission)."""
    found = Contents(root)
    try:
        top = list(os.scandir(root))
    except FileNotFoundError:
        return found
    for item in sorted(top, key=lambda d: d.name):
        kind = BY_FOLDER.get(item.name)
        if kind is None or not item.is_dir(follow_symlinks=False):
            found.foreign.append(Path(item.path))
            continue
        try:
            inside = sorted(os.scandir(item.path), key=lambda d: d.name)
        except FileNotFoundError:
            continue
        for one in inside:
            path = Path(one.path)
            try:
                info = os.lstat(path)
            except FileNotFoundError:
                continue
            folder, regular = stat.S_ISDIR(info.st_mode), stat.S_ISREG(info.st_mode)
            entry = kind.entry.fullmatch(one.name) and (folder if kind.folders else regular)
            partial = kind.partial.fullmatch(one.name) and (folder or regular)
            if not (entry or partial):  # a link, or a name cotwin does not write
                found.foreign.append(path)
                continue
            size = _folder_size(path) if folder else info.st_size
            found.entries.append(Entry(kind, path, size, info.st_mtime, partial=not entry))
    return found


# ---- entries in use -----------------------------------------------------------------------------

class Held:
    """A shared lock on an entry in use; `release` when it is no longer loaded (or never: it ends with the process)."""

    def __init__(self, fd: int):
        self.fd = fd

    def release(self) -> None:
        if self.fd >= 0:
            try:
                os.close(self.fd)
            except OSError:
                pass
            self.fd = -1

    __del__ = release  # a hold forgotten (an instance that failed half way) ends with its object


def _same(path: Path, fd: int) -> bool:
    """Whether `path` still names the file or folder open as `fd` (not removed or replaced meanwhile)."""
    try:
        now, held = os.stat(path), os.fstat(fd)
    except OSError:
        return False
    return (now.st_dev, now.st_ino) == (held.st_dev, held.st_ino)


def hold(path: str | Path) -> Held | None:
    """A shared lock on the entry at `path` (a file, or an extracted FMU's folder), its mtime set to now; None
    when it is not there (never was, or an eviction is removing it now): the caller builds it again."""
    path = Path(path)
    try:
        fd = os.open(path, os.O_RDONLY | os.O_CLOEXEC | os.O_NOFOLLOW)
    except OSError:
        return None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)  # refused only while an eviction removes it
        except OSError as err:
            if err.errno in (errno.EWOULDBLOCK, errno.EINTR):
                raise
            # a file system without locks (ENOLCK): used unlocked (and, as remove cannot lock, never evicted)
        if not _same(path, fd):
            raise FileNotFoundError(errno.ENOENT, "removed", str(path))
    except OSError:
        os.close(fd)
        return None
    touch(path)
    return Held(fd)


def touch(path: str | Path) -> None:
    """The entry at `path` marked as used now (its mtime); nothing on a cache that cannot be written."""
    try:
        os.utime(path)
    except OSError:
        pass


def remove(entry: Entry) -> bool:
    """Remove `entry` unless a running process holds it (`hold`); whether it was removed. A folder is renamed
    first (a partial name) and then deleted, so that no one finds it half removed."""
    try:
        fd = os.open(entry.path, os.O_RDONLY | os.O_CLOEXEC | os.O_NOFOLLOW)
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        if not _same(entry.path, fd):
            return False
        if stat.S_ISDIR(os.fstat(fd).st_mode):
            if entry.partial:  # already under a partial name, which no reader takes: removed where it is
                gone = entry.path  # (renamed again, '..name' would be no name of cotwin's: a folder left foreign)
            else:
                gone = entry.path.with_name(f".{entry.path.name}.{os.getpid()}.0")  # kind.partial's form
                os.rename(entry.path, gone)
            shutil.rmtree(gone, ignore_errors=True)
        else:
            os.unlink(entry.path)
        return True
    except OSError:  # held (EWOULDBLOCK), removed meanwhile, or a cache that cannot be written
        return False
    finally:
        os.close(fd)


# ---- the bound ----------------------------------------------------------------------------------

def read_cap(environ=os.environ) -> tuple[int, str | None]:
    """The cap in bytes from COTWIN_CACHE_MAX_MB (MiB, a number >= 0; default 512), and what was wrong with
    the value given, if anything (then the default)."""
    text = environ.get("COTWIN_CACHE_MAX_MB", "").strip()
    if not text:
        return DEFAULT_CAP_MB * MiB, None
    try:
        value = float(text)
    except ValueError:
        value = -1.0
    if not (0 <= value < 1e12):  # also nan and inf
        return DEFAULT_CAP_MB * MiB, f"COTWIN_CACHE_MAX_MB={text!r} is not a number of MiB >= 0: {DEFAULT_CAP_MB} taken"
    return int(value * MiB), None


def evict(root: Path, cap: int, keep: Path | None = None, now: float | None = None) -> list[Entry]:
    """Least recently used entries of the rebuildable kinds removed from `root` until its size is at most `cap`
    (entries held, younger than FRESH, or `keep` are not); the entries removed. Leftover partial files of killed
    processes go first. OSError when `root` cannot be listed."""
    found = contents(root)
    total = found.size
    now = time.time() if now is None else now
    removed = []
    candidates = sorted((e for e in found.entries if e.kind.rebuildable or e.partial),
                        key=lambda e: (not e.partial, e.used))
    for entry in candidates:
        if total <= cap:
            break
        if entry.path == keep or now - entry.used < FRESH:
            continue
        if remove(entry):
            total -= entry.size
            removed.append(entry)
    return removed


def bound(written: str | Path | None = None) -> None:
    """After cotwin wrote the entry `written` into the cache: evict (see module doc) if the cache is over its
    cap. Never raises: the cache is an optimisation."""
    root = cache_dir()
    if root is None:
        return
    try:
        evict(root, read_cap()[0], Path(written) if written is not None else None)
    except (OSError, ValueError):
        pass


# ---- the command's work -------------------------------------------------------------------------

def refusal(path: Path, message: str) -> CotwinError:
    """A refusal of the cache command, located at `path` (the cache folder, or COTWIN_CACHE)."""
    return CotwinError([Finding(Location(str(path), 0, 0), Severity.ERROR, message)])


def located(off_ok: bool = False) -> Path | None:
    """The cache folder, or a located CotwinError when it is not a folder, or there is none (COTWIN_CACHE=off: None
    with `off_ok`)."""
    root = cache_dir()
    if root is None and off_ok:
        return None
    if root is None:
        raise refusal(Path("COTWIN_CACHE"), "COTWIN_CACHE=off: cotwin keeps no cache, so there is none to clear")
    if root.exists() and not root.is_dir():
        raise refusal(root, "COTWIN_CACHE names a file, not a folder: cotwin keeps no cache there (and will not "
                             "remove it); name a folder")
    return root


@dataclass
class Cleared:
    removed: list[Entry]
    kept: list[Entry]  # in use by a running process, or partial files being written


def clear(root: Path) -> Cleared:
    """Every entry of cotwin's in `root` removed, except those held or partial files younger than FRESH; the
    kind folders and `root` too when left empty. A located CotwinError, before anything is removed, when
    `root` holds anything cotwin did not write."""
    try:
        found = contents(root)
    except OSError as err:
        raise refusal(root, f"cannot read the cache: {err.strerror or err}") from None
    if found.foreign:
        names = ", ".join(str(p.relative_to(root)) for p in found.foreign[:5])
        more = f" and {len(found.foreign) - 5} more" if len(found.foreign) > 5 else ""
        raise refusal(root, f"not cotwin's cache alone: it holds {len(found.foreign)} file(s) cotwin did not write "
                             f"({names}{more}), so nothing was removed; move them out, or point COTWIN_CACHE at a "
                             "folder of cotwin's own")
    now = time.time()
    removed, kept = [], []
    locks = {e.path for e in found.entries if e.path.name.endswith(".lock")}
    for entry in found.entries:
        if entry.path in locks:  # after its solutions file
            continue
        if entry.partial and now - entry.used < FRESH:
            kept.append(entry)
        elif remove(entry):
            removed.append(entry)
        else:
            kept.append(entry)
    for path in sorted(locks):  # an IK file's lock, unless another process saves it now
        entry = next(e for e in found.entries if e.path == path)
        (removed if remove(entry) else kept).append(entry)
    for kind in KINDS:
        try:
            (root / kind.folder).rmdir()
        except OSError:  # not empty, or not there
            pass
    try:
        root.rmdir()
    except OSError:
        pass
    return Cleared(removed, kept)


def size_text(n: int) -> str:
    """A size as people read it: 512 bytes, 12.3 KiB, 4.5 MiB, 1.2 GiB."""
    for unit, scale in (("GiB", 1 << 30), ("MiB", MiB), ("KiB", 1 << 10)):
        if n >= scale:
            return f"{n / scale:.1f}".removesuffix(".0") + f" {unit}"
    return f"{n} bytes"
