"""Where evaluations run: the Executor interface and the serial executor (base), local worker
processes that survive their workers (process_pool), and a Dask distributed cluster
(dask_cluster). The run loop knows only the interface; executor plugins announce the rest."""
