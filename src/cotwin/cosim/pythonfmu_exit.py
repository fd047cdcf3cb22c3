"""Release pythonfmu's interpreter guard before a Python process that loaded Python FMUs exits.

pythonfmu's export library (the binary of every Python FMU, ours included) keeps its interpreter guard in
a static `shared_ptr` and resets it from an ELF destructor. glibc cannot unload that library (it has
STB_GNU_UNIQUE symbols, so `dlclose` keeps it), so at exit the `shared_ptr`'s static destructor frees the
guard first and the ELF destructor then releases it a second time: a use-after-free (valgrind: "Invalid
read ... finalizePythonInterpreter ... block free'd in __run_exit_handlers") that glibc sometimes catches
as "corrupted double-linked list" and aborts, after every row was written. Calling the library's exported
`finalizePythonInterpreter` from an `atexit` hook, while the interpreter still runs, releases the guard
once and leaves a null pointer for both exit paths. Upstream: NTNU-IHB/PythonFMU#228.
"""
from __future__ import annotations

import atexit
import ctypes
import os
import sys

SYMBOL = "finalizePythonInterpreter"
_installed = False


def loaded_libraries() -> list[str]:
    """Paths of the shared libraries mapped into this process, once each (Linux; empty elsewhere).
    A library whose file was removed (an FMU's extraction folder, cleaned up) keeps its name."""
    try:
        with open("/proc/self/maps", encoding="utf-8", errors="replace") as maps:
            lines = maps.read().splitlines()
    except OSError:
        return []
    paths: dict[str, None] = {}
    for line in lines:
        fields = line.split(maxsplit=5)
        if len(fields) == 6 and fields[5].startswith("/"):
            path = fields[5].removesuffix(" (deleted)")
            if ".so" in os.path.basename(path):
                paths[path] = None
    return list(paths)


def release_guards() -> int:
    """Release the interpreter guard of every loaded pythonfmu library; returns how many were released.
    Only libraries already loaded are looked at (RTLD_NOLOAD): none is loaded by this."""
    released = 0
    for path in loaded_libraries():
        try:
            library = ctypes.CDLL(path, mode=os.RTLD_NOLOAD | os.RTLD_LAZY)
        except OSError:
            continue
        try:
            release = library[SYMBOL]
        except AttributeError:
            continue
        release.argtypes = []
        release.restype = None
        release()
        released += 1
    return released


def install() -> None:
    """Register `release_guards` to run when the interpreter exits (once per process)."""
    global _installed
    if not _installed and sys.platform == "linux":  # the ELF destructor is pythonfmu's Linux path
        atexit.register(release_guards)
        _installed = True
