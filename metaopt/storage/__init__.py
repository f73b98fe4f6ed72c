"""What is kept: every run and evaluation in an embedded SQLite run store (run_store), which
runs make up an experiment's cells (experiment_store), a run's evaluations written out as
CSV or JSON (export), and any output file written whole or not at all (whole_file); the
store's limits (limits) stand apart, free of SQLite, for whatever checks a value by them."""
