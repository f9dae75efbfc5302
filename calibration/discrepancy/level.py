"""The diagnosis verdict's false-alarm level and the bootstrap size that resolves it."""

# The verdict's false-alarm level, family-wise over its two tests (each at ALPHA / 2), and
# the bootstrap replicates that can resolve ALPHA / 2 (p = 1/(B + 1) needs B >= 2/ALPHA - 1).
# Why 0.5 % and not 1 %: a lab reads "mismatch" as a defect to chase. At α = 1 % the
# measured rate sat at its nominal 1.2-1.3 % on recordings the tests were not built on
# (heavy-tailed real noise, re-seating; docs/benchmarks.md), so "at most 1 %" could not be
# promised; at 0.5 % it holds with its 95 % interval, for a few % of power at 2x the
# detectable size and twice the bootstrap's time (seconds on a campaign).
ALPHA = 0.005
N_NULL = 400
