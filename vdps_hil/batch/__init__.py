"""Many drives: batch replay, diagnosis and Monte Carlo studies as tasks on a local Dask
cluster (default), an existing Dask cluster, a process pool or inline, with resume keys, a
progress bar and a fleet report.

Data flow. ``tasks`` turns files (or study trials, ``studies``) into :class:`~.worker.Task` s
with resume keys (``keys``); ``runner.run_batch`` skips those whose result file holds the same
key, hands the rest to an ``engine.Engine`` backend, whose workers run each with
``worker.execute`` (a failure is data, never a stopped batch); every outcome is written to
``<out>/drives/<id>.json`` as it finishes and counted by ``progress``; the aggregate
``<out>/batch.json`` at the end feeds the fleet report (``report``, HTML with plots).
"""
