"""Result files written on a thread of their own (cotwin.cosim.appender): in order, in whole lines, a write the
file system takes only in part cut back and said, with the rows written before kept and the run's other
endings still made; the rows' text spelt without the GIL where Python's own functions are asked."""

from __future__ import annotations

import os
import resource
import signal
import struct
import threading
from contextlib import contextmanager

import numpy as np
import pytest

from cotwin.cosim import rowtext
from cotwin.cosim.algorithm import Jacobi
from cotwin.cosim.appender import Appender
from cotwin.cosim.execution import Execution
from cotwin.cosim.observers import CSVWriter, Observer
from cotwin.cosim.system import System
from cotwin.cosim.units import Port, PythonUnit
from cotwin.diagnostics import CotwinError


@contextmanager
def file_size_limit(size: int):
    """Files this process writes may not grow past `size` bytes (a write past it is cut short, then EFBIG)."""
    previous_limit = resource.getrlimit(resource.RLIMIT_FSIZE)
    previous_handler = signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (size, previous_limit[1]))
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, previous_limit)
        signal.signal(signal.SIGXFSZ, previous_handler)


def test_pieces_are_written_in_order_spelt_on_the_thread(tmp_path):
    path = tmp_path / "f"
    fd = os.open(path, os.O_WRONLY | os.O_CREAT)
    threads = set()

    def spell(n: int) -> bytes:
        threads.add(threading.current_thread().name)
        return f"{n}\n".encode()

    file = Appender(fd, spell, name="spelling")
    for k in range(500):
        file.put(k if k % 3 else f"b{k}\n".encode())
    file.drain()
    file.stop()
    os.close(fd)
    assert path.read_text().splitlines() == [str(k) if k % 3 else f"b{k}" for k in range(500)]
    assert threads == {"spelling"} and file.lines == 500 and file.size == path.stat().st_size


def test_a_write_taken_in_part_is_cut_back_to_whole_lines_and_its_error_raised(tmp_path):
    path = tmp_path / "f"
    fd = os.open(path, os.O_WRONLY | os.O_CREAT)
    file = Appender(fd, bytes)
    with file_size_limit(1000):
        file.put(b"x" * 599 + b"\n")
        file.drain()
        file.put(b"w" * 99 + b"\n" + b"y" * 599 + b"\n")  # 400 bytes of it fit: its first line, and part of the next
        with pytest.raises(OSError):
            file.drain()
        with pytest.raises(OSError):  # and nothing after it is written
            file.put(b"z\n")
        file.stop()
    os.close(fd)
    assert path.read_bytes() == b"x" * 599 + b"\n" + b"w" * 99 + b"\n"
    assert file.lines == 2 and file.size == 700


class Count(PythonUnit):
    def __init__(self):
        super().__init__("{c}.c", [Port("r", "Real", "output")])
        self.values.update(r=0.0)

    def step(self, t: float, h: float) -> None:
        self.values["r"] = t / 3


class Ended(Observer):
    """Records that the run's ending reached it."""
    ended = False

    def step_complete(self, execution) -> None: ...

    def simulation_ended(self, execution, error) -> None:
        self.ended = True


def test_a_result_file_that_takes_no_more_names_itself_keeps_whole_rows_and_the_other_endings_are_made(tmp_path):
    warm = Execution(System.of([Count()], [], log={"{c}.c": ["r"]}), Jacobi(), 0.001,
                     observers=[CSVWriter(tmp_path / "warm.csv")])
    warm.run(0.01)  # the C that spells rows is built (and cached) before files may not grow
    writer, after = CSVWriter(tmp_path / "out.csv", batch=64), Ended()
    (tmp_path / "out.csv").write_text("an earlier result\n")
    execution = Execution(System.of([Count()], [], log={"{c}.c": ["r"]}), Jacobi(), 0.001, observers=[writer, after])
    with file_size_limit(20000), pytest.raises(CotwinError) as raised:
        execution.run(2.0)
    assert "out.csv" in str(raised.value) and "cannot write the results" in str(raised.value)
    assert after.ended, "an observer after the writer was not told the run ended"
    kept = (tmp_path / "out.partial.csv").read_text()
    assert kept.endswith("\n") and kept.startswith("time,")
    rows = kept.splitlines()[1:]
    assert rows and all(len(row.split(",")) == 2 for row in rows)
    assert [float(row.split(",")[0]) for row in rows] == pytest.approx([0.001 * k for k in range(len(rows))])
    assert writer.kept().startswith(f"the first {len(rows)} of the {writer.rows} row(s) computed are in")
    assert (tmp_path / "out.csv").read_text() == "an earlier result\n"
    assert not [p.name for p in tmp_path.iterdir() if p.name.endswith(".part")]


def test_rows_are_spelt_without_the_gil_as_repr_spells_them_also_where_python_is_asked(tmp_path):
    if not rowtext.available():
        pytest.skip("no C compiler here: rows are spelt in Python")
    generator = np.random.default_rng(23)
    doubles = [struct.unpack("<d", struct.pack("<Q", int(b)))[0]
               for b in generator.integers(0, 2 ** 63 - 2 ** 52, size=20000, dtype=np.uint64)]
    rows = np.array([d for d in doubles if np.isfinite(d)], dtype=np.float64).reshape(-1, 1)
    want = "".join(f"{float(k)!r},{v!r}\n" for k, v in enumerate(rows[:, 0].tolist()))
    got: list = [None, None]

    def spell(i: int) -> None:
        got[i] = rowtext.rows_text(rows, [0], "r", times=[float(k) for k in range(len(rows))])

    threads = [threading.Thread(target=spell, args=(i,)) for i in range(2)]
    for thread in threads:
        thread.start()
    busy = sum(len(repr(k)) for k in range(200000))  # Python runs on this thread meanwhile
    for thread in threads:
        thread.join()
    assert busy and got == [want, want]
