"""Assessing candidates a run found: naming one (a stored gait, a run's best, RUN:NUMBER),
replaying it on the same or changed settings, and its table over a problem's perturbations."""
