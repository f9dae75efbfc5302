"""Clopper–Pearson intervals for the gen3 false-alarm counts (issue 22)."""

from __future__ import annotations

from scipy.stats import beta


def clopper_pearson(k: int, n: int, level: float = 0.95) -> tuple[float, float]:
    """Exact two-sided interval for k successes in n trials."""
    if n <= 0:
        return (0.0, 1.0)
    a = (1.0 - level) / 2.0
    lo = 0.0 if k == 0 else float(beta.ppf(a, k, n - k + 1))
    hi = 1.0 if k == n else float(beta.ppf(1.0 - a, k + 1, n - k))
    return (lo, hi)


def rate_text(k: int, n: int) -> str:
    """"k/n = r % [lo, hi] %"."""
    lo, hi = clopper_pearson(k, n)
    r = 100.0 * k / n if n else 0.0
    return f"{k}/{n} = {r:.2f} % [{100 * lo:.2f}, {100 * hi:.2f}] %"
