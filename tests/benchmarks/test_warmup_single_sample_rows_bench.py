"""benchmarks/bench_warmup_single_sample_rows: the solver's first-stage decision, with and
without the held-out blocks' means test, and the test restored afterwards."""

from __future__ import annotations

from benchmarks.bench_warmup_single_sample_rows import degree_chosen
from calibration import warmup


def test_the_share_rule_alone_misses_what_the_block_means_establish():
    saved = warmup._block_means_beat
    assert degree_chosen(18000, 10e-3, seed=0, strong=False) == 0
    assert warmup._block_means_beat is saved
    assert degree_chosen(18000, 10e-3, seed=0, strong=True) > 0
    assert degree_chosen(18000, 0.0, seed=0, strong=True) == 0
