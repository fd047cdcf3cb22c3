"""Whether a threaded sweep's thread count fits the machine: its CPUs, and its memory at a measured cost per thread.

A what-if's physics keeps one CPU busy (the native loop runs outside Python's lock), so threads beyond the CPUs
this process may use take turns and add no speed; each thread also holds its own forks of the twin (the simulator,
the d-model FMU's instance, the mapping), whose memory is measured on the running process (cotwin.twin.analysis.
sweep.fork_footprint) rather than guessed. Linux's /proc gives the figures; elsewhere the memory is not judged.
"""

from __future__ import annotations

import os
from pathlib import Path

MANY = 2  # threads per usable CPU beyond which a sweep is warned (a few more than the CPUs cost little)
MB = 1024 * 1024


def usable_cpus() -> int:
    """The CPUs this process may run on (its affinity, e.g. a container's share), else the machine's."""
    try:
        return len(os.sched_getaffinity(0)) or 1
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def available_memory(meminfo: Path = Path("/proc/meminfo")) -> int | None:
    """Bytes of memory the kernel says can be had without swapping (MemAvailable); None where it does not say."""
    try:
        for line in meminfo.read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def resident_memory(statm: Path = Path("/proc/self/statm")) -> int | None:
    """Bytes of this process's memory resident now; None where /proc does not say."""
    try:
        return int(statm.read_text().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError, AttributeError):
        return None


def thread_warnings(threads: int, cpus: int, per_thread: int | None, available: int | None) -> list[str]:
    """What is unwise about running `threads` what-ifs at once on `cpus` CPUs, each thread taking `per_thread`
    bytes, with `available` bytes free (None: not known, not judged): warnings, not errors (the sweep may still
    be what the user wants, e.g. to measure)."""
    out = []
    if threads > MANY * cpus:
        out.append(f"{threads} threads on {cpus} CPU{'s' if cpus != 1 else ''}: each what-if's physics keeps a CPU "
                   f"busy, so the threads beyond {cpus} take turns and the sweep is no faster than with {cpus}, while "
                   f"every thread holds its own forks of the twin in memory")
    if per_thread and available is not None and threads * per_thread > available:
        out.append(f"{threads} threads need about {threads * per_thread / MB:.0f} MB of memory, more than the "
                   f"{available / MB:.0f} MB available: each holds its own forks of the twin, about "
                   f"{per_thread / MB:.1f} MB (what one more fork added to this process, measured just now); the "
                   f"sweep may be killed for want of memory: about {max(1, available // per_thread)} threads fit")
    return out
