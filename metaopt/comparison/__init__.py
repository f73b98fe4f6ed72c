"""Comparing optimizers and engines: an experiment's grid of optimizers x problem settings x
seeds (experiment), running it so that a re-run does only what is left (runner), the cells'
statistics and tests (summary), and runs' bests replayed on the other physics engines
(transfer)."""
