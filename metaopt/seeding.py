"""Deriving reproducible seeds: one run seed gives every evaluation its own seed."""

from __future__ import annotations

_MASK64 = (1 << 64) - 1


def _splitmix64(value: int) -> int:
    """One round of SplitMix64 (Steele et al. 2014): a fast, well-mixed 64-bit hash."""
    value = (value + 0x9E3779B97F4A7C15) & _MASK64
    value = ((value ^ (value >> 30)) * 0xBF58476D1CE4E5B9) & _MASK64
    value = ((value ^ (value >> 27)) * 0x94D049BB133111EB) & _MASK64
    return value ^ (value >> 31)


class EvaluationSeeds:
    """The seed of evaluation ``index`` of a run depends only on (run seed, index).

    So a candidate evaluates the same whatever executor, worker or order runs it. Seeds fit in
    63 bits (take ``% 2**32`` where an engine wants 32).
    """

    def __init__(self, run_seed: int) -> None:
        self._run_key = _splitmix64(run_seed & _MASK64)

    def __call__(self, index: int) -> int:
        """The seed of evaluation ``index``."""
        return _splitmix64(self._run_key ^ index) >> 1


class CommonSeeds:
    """Common random numbers: evaluation ``index`` of a run resampling every candidate
    ``count`` times gets sample ``index % count``'s seed, so every candidate is evaluated on
    the same ``count`` seeds and the differences between candidates are not seed noise."""

    def __init__(self, run_seed: int, count: int) -> None:
        self._seeds = EvaluationSeeds(run_seed)
        self._count = count

    def __call__(self, index: int) -> int:
        """The seed of evaluation ``index``: that of sample ``index % count``."""
        return self._seeds(index % self._count)
