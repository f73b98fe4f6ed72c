"""What people look at: the terminal's tables and progress bar (display), tables shown in the
terminal or written as CSV (result_table), user text shown as typed in both (plain),
convergence curves (convergence) and their figures (plots), a run's figures (report) and a
video of a candidate (video)."""
