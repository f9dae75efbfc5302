"""Pure functions of a temperature series are computed once per distinct series."""

from __future__ import annotations

import numpy as np

from calibration import series_memo
from calibration.rebuild_rate_noise import rebuild_rate_noise
from calibration.series_memo import memo_by_value, value_key
from calibration.temperature_conditioning import rate_noise_c_per_min
from calibration.temperature_dequantise import dequantise
from tests.calibration.dequantise_cases import captures, overshoot


def test_a_key_is_the_values_not_the_object():
    a = np.linspace(0.0, 1.0, 50)
    assert value_key(a) == value_key(a.copy())
    changed = a.copy()
    changed[17] += 1e-12
    assert value_key(a) != value_key(changed)
    assert value_key(a) != value_key(a.astype(np.float32))
    assert value_key(a) != value_key(a.reshape(5, 10))
    assert value_key((a, 2.0, None)) == value_key((a.copy(), 2.0, None))


def test_a_memo_computes_once_per_distinct_values_and_hands_out_copies():
    calls: list[int] = []

    @memo_by_value
    def doubled(x: np.ndarray, k: float = 2.0) -> np.ndarray:
        calls.append(1)
        return k * x

    x = np.arange(5.0)
    first = doubled(x)
    first[0] = 99.0  # a caller writing into its result does not change the next one's
    again = doubled(x.copy())
    assert len(calls) == 1 and again[0] == 0.0
    assert doubled(x, k=3.0)[1] == 3.0 and len(calls) == 2
    for i in range(series_memo.MEMO_SIZE + 1):  # the least recently used is dropped
        doubled(np.full(3, float(i)))
    doubled(x)
    assert len(calls) == 2 + series_memo.MEMO_SIZE + 1 + 1


def test_a_series_rebuilt_again_is_the_first_rebuild_and_not_shared():
    t, temp, _ = captures(overshoot, 0.0, 5.0)  # a coarse channel's capture means
    first = dequantise(t, temp)
    assert first.rebuilt
    rebuilt = first.temperature_c.copy()
    first.temperature_c[:] = 0.0  # the caller's own copy
    again = dequantise(t.copy(), temp.copy())
    np.testing.assert_array_equal(again.temperature_c, rebuilt)
    # the rebuild's rate error: one set of draws per series, whichever fit asks
    noise = rebuild_rate_noise(t, again)
    assert rebuild_rate_noise(t.copy(), dequantise(t, temp)) is noise
    assert noise(60.0) > 0.0


def test_the_rate_noise_of_equal_times_is_computed_once(monkeypatch):
    import calibration.temperature_conditioning as tc

    t = np.arange(200, dtype=float)
    calls: list[int] = []
    real = tc.temperature_rates_c_per_min

    def counting(*args, **kwargs):  # type: ignore[no-untyped-def]
        calls.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(tc, "temperature_rates_c_per_min", counting)
    rate_noise_c_per_min.cache_clear()  # type: ignore[attr-defined]
    first = rate_noise_c_per_min(t, 40.0, 0.0123)
    assert rate_noise_c_per_min(t.copy(), 40.0, 0.0123) == first
    assert len(calls) == 1
    rate_noise_c_per_min(t, 40.0, 0.0124)
    assert len(calls) == 2


def test_a_long_series_is_computed_each_time_not_kept():
    # A service calibrating many long logs must not hold each one's series: calls on more
    # than MEMO_MAX_BYTES of arrays go straight to the function.
    calls: list[int] = []

    @memo_by_value
    def total(x: np.ndarray) -> float:
        calls.append(1)
        return float(np.sum(x))

    long = np.ones(series_memo.MEMO_MAX_BYTES // 8 + 1)
    assert total(long) == total(long.copy()) == long.size
    assert len(calls) == 2
    short = np.ones(10)
    total(short)
    total(short.copy())
    assert len(calls) == 3
