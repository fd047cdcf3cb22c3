"""Checks of plain data read back from outside (a saved state), against what it is restored into.

Each check returns the value (or raises StateError) and names the place in the state that is wrong, e.g.
"the saved state's unit {mapping}.mapping's time is nan, not a finite number". They live below every
package that saves a state (the simulator, the mapping, the co-simulation), so each checks its own part.
"""

from __future__ import annotations

import math
from typing import Iterable

import numpy as np

from .diagnostics import CotwinError
from .robosim.values import CAPACITY, SeqValue, SetValue


class StateError(CotwinError):
    """Bytes that are not a cotwin state of the expected kind, or a state that does not fit what it is
    restored into."""


def fields(data, what: str, required: Iterable[str], optional: Iterable[str] = ()) -> dict:
    """`data` as a dict with every `required` key and no key beyond `optional`, else StateError saying
    which are missing or unexpected."""
    required = list(required)
    if data.__class__ is not dict:
        raise StateError(f"the saved state's {what} is not a table of {', '.join(required)}")
    missing = [k for k in required if k not in data]
    extra = [k for k in data if k not in required and k not in optional]
    if missing or extra:
        parts = ([f"lacks {', '.join(map(str, missing))}"] if missing else []) + \
                ([f"has unexpected {', '.join(repr(k)[:40] for k in extra[:10])}"] if extra else [])
        raise StateError(f"the saved state's {what} {' and '.join(parts)}")
    return data


def finite(value, what: str, low: float = -math.inf) -> float:
    """A finite number at least `low`."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)) \
            or not math.isfinite(value) or value < low:
        bound = "" if low == -math.inf else f" at least {low:g}"
        raise StateError(f"the saved state's {what} is {value!r:.60}, not a finite number{bound}")
    return float(value)


def count(value, what: str, high: int | None = None) -> int:
    """A whole number from 0 to `high`."""
    if value.__class__ is not int or value < 0 or (high is not None and value > high):
        raise StateError(f"the saved state's {what} is {value!r:.60}, not a whole number from 0"
                         + (f" to {high}" if high is not None else ""))
    return value


def of_type(value, kind: type | tuple, what: str):
    """`value` if it is a `kind` (Booleans are not integers here)."""
    if not isinstance(value, kind) or (isinstance(value, bool) and bool not in (kind if isinstance(kind, tuple) else (kind,))):
        names = " or ".join(k.__name__ for k in (kind if isinstance(kind, tuple) else (kind,)))
        raise StateError(f"the saved state's {what} is {value!r:.60}, not a {names}")
    return value


PLAIN = {"Boolean": frozenset((bool,)), "Integer": frozenset((int,)), "Real": frozenset((int, float))}  # per FMI
# type, the Python classes of its values taken as they are (numpy's scalars are checked one by one below)


def port_value(value, fmi_type: str, what: str):
    """A port's value of its FMI type: a number for a Real (any float: NaN and infinities are readings too),
    a whole number for an Integer, a Boolean for a Boolean."""
    if value.__class__ in PLAIN.get(fmi_type, ()):
        return value
    if fmi_type == "Boolean" and isinstance(value, (bool, np.bool_)):
        return value
    if fmi_type == "Integer" and isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_)):
        return value
    if fmi_type == "Real" and isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_)):
        return value
    raise StateError(f"the saved state's {what} is {value!r:.60}, not a{'n' if fmi_type[0] in 'IA' else ''} {fmi_type}")


def like(value, template, what: str):
    """`value` if it has the shape of `template`, the live value it replaces: the same kind of scalar (a
    float may be an integer), the same keys of a record, the same class and size of a vector, matrix or
    tuple (a plain tuple too: the mapping's functions return them), a sequence or set of at most CAPACITY
    elements, an array of the same dtype and shape."""
    if template is None:
        return value
    if isinstance(template, (bool, np.bool_)):
        return of_type(value, (bool, np.bool_), what)
    if isinstance(template, (int, np.integer)):
        return of_type(value, (int, np.integer), what)
    if isinstance(template, (float, np.floating)):
        return of_type(value, (int, float, np.integer, np.floating), what)
    if isinstance(template, str):
        return of_type(value, str, what)
    if isinstance(template, np.ndarray):
        if not isinstance(value, np.ndarray) or value.dtype != template.dtype or value.shape != template.shape:
            raise StateError(f"the saved state's {what} is not an array of {template.shape} {template.dtype}")
        return value
    if isinstance(template, dict):
        fields(value, what, list(template))
        return {k: like(value[k], template[k], f"{what}.{k}") for k in template}
    if isinstance(template, (SeqValue, SetValue)):
        kind = tuple if isinstance(template, SeqValue) else (set, frozenset)
        if not isinstance(value, kind) or len(value) > CAPACITY:
            raise StateError(f"the saved state's {what} is not a {type(template).__name__} of at most {CAPACITY} elements")
        return value
    if isinstance(template, (tuple, list)):  # a vector, matrix or product (a plain tuple where a mapping made one)
        if not isinstance(value, tuple if isinstance(template, tuple) else list) or len(value) != len(template):
            raise StateError(f"the saved state's {what} is not a {type(template).__name__} of {len(template)} elements")
        return value.__class__(like(v, t, f"{what}[{k}]") for k, (v, t) in enumerate(zip(value, template)))
    if value.__class__ is not template.__class__:
        raise StateError(f"the saved state's {what} is a {type(value).__name__}, not a {type(template).__name__}")
    return value
