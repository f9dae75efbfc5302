"""ADXL355 data conversions: 20-bit acceleration counts and the 12-bit temperature channel."""

from __future__ import annotations

import numpy as np

#: Nominal sensitivity, LSB/g, per full-scale range (datasheet typical).
LSB_PER_G: dict[float, float] = {2.0: 256_000.0, 4.0: 128_000.0, 8.0: 64_000.0}
COUNT_MIN = -(1 << 19)  # 20-bit two's complement
COUNT_MAX = (1 << 19) - 1
TEMP_RAW_AT_25C = 1885.0
TEMP_LSB_PER_C = -9.05
#: Fixed id registers 0x00..0x02 (data sheet register map): DEVID_AD, DEVID_MST, PARTID.
DEVID_AD, DEVID_MST, PARTID = 0xAD, 0x1D, 0xED
#: REVID (0x03) of the parts the simulators model; the real value varies by silicon revision.
REVID_SIM = 0x01


def lsb_per_g(range_g: float) -> float:
    try:
        return LSB_PER_G[float(range_g)]
    except KeyError:
        raise ValueError(f"ADXL355 range must be one of ±2, ±4, ±8 g, got {range_g}") from None


def counts_from_20bit(word: int) -> int:
    """Unsigned 20-bit register value (0…0xFFFFF) → signed count."""
    word &= 0xFFFFF
    return word - (1 << 20) if word & 0x80000 else word


def counts_to_20bit(count: int) -> int:
    """Signed count → unsigned 20-bit word; raises ValueError outside −524288…524287."""
    if not COUNT_MIN <= count <= COUNT_MAX:
        raise ValueError(f"{count} outside the 20-bit range {COUNT_MIN}..{COUNT_MAX}")
    return count & 0xFFFFF


def g_to_counts(g: np.ndarray, range_g: float) -> np.ndarray:
    """Quantise g to integer counts, saturating at the 20-bit limits."""
    c = np.rint(np.asarray(g, dtype=float) * lsb_per_g(range_g))
    return np.clip(c, COUNT_MIN, COUNT_MAX).astype(np.int64)


def counts_to_g(counts: np.ndarray | float, range_g: float) -> np.ndarray:
    return np.asarray(counts, dtype=float) / lsb_per_g(range_g)


def temp_raw_to_c(raw: np.ndarray | float) -> np.ndarray:
    """°C = 25 + (raw − 1885) / (−9.05)."""
    return 25.0 + (np.asarray(raw, dtype=float) - TEMP_RAW_AT_25C) / TEMP_LSB_PER_C


def temp_c_to_raw(temp_c: np.ndarray | float) -> np.ndarray:
    """Inverse of :func:`temp_raw_to_c`, rounded to the 12-bit channel."""
    raw = np.rint(TEMP_RAW_AT_25C + (np.asarray(temp_c, dtype=float) - 25.0) * TEMP_LSB_PER_C)
    return np.clip(raw, 0, 4095).astype(np.int64)


def is_saturated(counts: np.ndarray, range_g: float) -> bool:
    """Any sample at the nominal full scale (or the 20-bit limit)."""
    limit = range_g * lsb_per_g(range_g)
    return bool(np.any(np.abs(np.asarray(counts)) >= min(limit, COUNT_MAX)))
