"""Deriving reproducible seeds: one run seed gives every evaluation its own seed."""

from __future__ import annotations

_MASK64 = (1 << 64) - 1


def _splitmix64(value: int) -> int:
    """One round of SplitMix64 (Steele et al. 2014): a fast, well-mixed 64-bit hash."""
    value = (value + 0x9E3779B97F4A7C15) & _MASK64
    value = ((value ^ (value >> 30)) * 0xBF58476D1CE4E5B9) & _MASK64
    value = ((value ^ (value >> 27)) * 0x94D049BB133111EB) & _MASK64
    return value ^ (value >> 31)


def evaluation_seed(run_seed: int, index: int) -> int:
    """The seed of evaluation ``index`` of a run: depends only on (run_seed, index).

    So a candidate evaluates the same whatever executor, worker or order runs it. The result
    fits in 63 bits (any numpy or engine seed accepts it after ``% 2**32`` if needed).
    """
    return _splitmix64(_splitmix64(run_seed & _MASK64) ^ index) >> 1
