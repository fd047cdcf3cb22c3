"""Results computed once per model object: a Program, a kinematic tree or a MuJoCo model is not changed once
built, and what-if forks, sweeps and runs of one twin share it, so an analysis of it (the d-model's waits
and resting states, its generated sources, the robot's geoms) need not be made again per what-if."""

from __future__ import annotations

from functools import lru_cache
from types import CodeType
from typing import Callable, TypeVar

T = TypeVar("T")
SIZE = 32  # results kept (the objects they are of kept alive with them); the oldest dropped beyond

_KEPT: dict[tuple, tuple[object, object]] = {}  # (id(obj), key) -> (obj, result)


def once_per(obj: object, key: object, compute: Callable[[], T]) -> T:
    """compute() for `obj` and `key` (hashable), made once while obj is the same object (identity, not equality)."""
    slot = (id(obj), key)
    known = _KEPT.get(slot)
    if known is None or known[0] is not obj:
        if len(_KEPT) >= SIZE:
            _KEPT.pop(next(iter(_KEPT), None), None)  # another thread may have dropped it first
        known = _KEPT[slot] = (obj, compute())
    return known[1]  # type: ignore[return-value]


@lru_cache(maxsize=256)
def code(source: str, filename: str) -> CodeType:
    """`source` compiled (a code object is immutable, so one serves every exec of the same generated text): a
    run's fused loop and a mapping's event functions are the same text run after run, and compiling them
    costed about a millisecond a run."""
    return compile(source, filename, "exec")
