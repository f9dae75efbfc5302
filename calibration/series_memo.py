"""A pure function of a series, computed once per distinct series: a small memo keyed by value.

The rate check of a warm-up (:func:`calibration.warmup._rate_check`) measures dT/dt's noise
by running the rate method on draws of noise (a fixed seed) and, on a rebuilt temperature,
by redoing the rebuild (:mod:`calibration.rebuild_rate_noise`); the rebuild itself
(:func:`calibration.temperature_dequantise.dequantise`) is a function of the readings'
times and temperatures alone. Fits of one log that differ only in the accelerations (a
figure's refits, a noise study's draws) pass the same times and temperatures again: the
memo returns what the first call computed instead of computing it again.

The key is the arguments' values: an array by its dtype, shape and bytes (two arrays of
equal values are one key; a changed element is another), scalars and ``None`` as
themselves. A hit is exactly the first call's result, so only functions whose result
depends on nothing but their arguments (no clock, no unseeded draw, no global) may be
wrapped, and a caller must not modify a result in place (:func:`memo_by_value` hands a
copy of an array result out).
"""

from __future__ import annotations

import functools
from collections import OrderedDict
from collections.abc import Callable, Hashable
from typing import Any, TypeVar

import numpy as np

F = TypeVar("F", bound=Callable[..., Any])

# Distinct series kept per function: one log's fits and its redone rebuilds use a few.
MEMO_SIZE = 16
# Calls whose array arguments hold more than this are computed, not kept: a service that
# calibrates many long logs must not hold 16 of each one's series (a 2.4 M-row log's times
# and temperatures are 19 MB each), and on such a log the computation is a small share of
# the fit anyway.
MEMO_MAX_BYTES = 1 << 20


def value_key(value: Any) -> Hashable:
    """``value`` as a hashable key equal for equal values: arrays by dtype, shape and
    bytes, tuples and lists element by element, anything else hashable as itself."""
    if isinstance(value, np.ndarray):
        return ("ndarray", value.dtype.str, value.shape, np.ascontiguousarray(value).tobytes())
    if isinstance(value, (tuple, list)):
        return (type(value).__name__, tuple(value_key(v) for v in value))
    hash(value)  # an unhashable argument is a programming error here, not a miss
    return (type(value).__name__, value)


def _array_bytes(values: tuple[Any, ...]) -> int:
    """The bytes of the arrays among ``values`` (inside tuples and lists too)."""
    total = 0
    for v in values:
        if isinstance(v, np.ndarray):
            total += v.nbytes
        elif isinstance(v, (tuple, list)):
            total += _array_bytes(tuple(v))
    return total


def memo_by_value(fn: F) -> F:
    """``fn`` computed once per distinct argument values (module docstring); at most
    :data:`MEMO_SIZE` results kept, least recently used dropped first; calls on more than
    :data:`MEMO_MAX_BYTES` of arrays are not kept. An array result is handed out as a copy."""
    memo: OrderedDict[Hashable, Any] = OrderedDict()

    @functools.wraps(fn)
    def wrapped(*args: Any, **kwargs: Any) -> Any:
        if _array_bytes((*args, *kwargs.values())) > MEMO_MAX_BYTES:
            return fn(*args, **kwargs)
        key = (value_key(args), value_key(tuple(sorted(kwargs.items()))))
        if key in memo:
            memo.move_to_end(key)
        else:
            memo[key] = fn(*args, **kwargs)
            if len(memo) > MEMO_SIZE:
                memo.popitem(last=False)
        result = memo[key]
        return result.copy() if isinstance(result, np.ndarray) else result

    wrapped.cache_clear = memo.clear  # type: ignore[attr-defined]
    return wrapped  # type: ignore[return-value]
