"""Many drives: batch replay, diagnosis and Monte Carlo studies as tasks on a local Dask
cluster (default), an existing Dask cluster, a process pool or inline, with resume keys, a
progress bar and a fleet report.

``engine``   Task, Engine, run_batch (backends, failure model, result files)
``keys``     resume keys (input, config, vehicle/model files, effects, tool version)
``tasks``    task functions (replay, diagnose, study trials) and task builders
``report``   the fleet report (HTML with plots)
``progress`` counts, bar and ETA
"""
