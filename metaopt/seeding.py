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
    """Common random numbers: every candidate of a group is evaluated on the same ``count``
    seeds, so the differences between them are what they do, not seed noise.

    The group is the whole run (``batch_size`` None: the same ``count`` seeds throughout) or
    each batch of ``batch_size`` candidates (fresh seeds per batch, so a long run does not tune
    itself to a few worlds while the candidates compared in one batch still meet the same ones).
    """

    def __init__(self, run_seed: int, count: int, batch_size: int | None = None) -> None:
        self._seeds = EvaluationSeeds(run_seed)
        self._count = count
        self._batch_size = batch_size

    def __call__(self, index: int) -> int:
        """The seed of evaluation ``index`` (sample ``index % count`` of its candidate)."""
        sample = index % self._count
        if self._batch_size is None:
            return self._seeds(sample)
        batch = index // self._count // self._batch_size
        return self._seeds(batch * self._count + sample)
