"""The run store's limits, apart from the store (SQLite, threads) for what checks values by them."""

#: The largest integer the store keeps (SQLite's are signed 64-bit): the bound of every run id,
#: seed and budget, and of the command-line options that name one.
MAX_STORED_INT = 2**63 - 1
