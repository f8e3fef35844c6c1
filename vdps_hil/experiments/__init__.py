"""Experiments (layer 15): everything that reads simulator truth or scores against it.

Truth rule: simulator truth -- the ``/truth/`` topics of a simulated recording, a truth vehicle
file's parameters, ``Simulator.truth`` / ``.events``, a synthetic drive's ``Truth`` -- is read
only here and in ``sim/``. Nothing in the layers below (units ... bus, codecs, adapters,
record, model, estimation, identification, prediction, pipeline, workbench, realdata, app)
imports ``sim/`` or ``experiments/``, not even inside a function; the HIL bench and the batch
runner (layer 16) and the commands (layer 17) may.

Data flow: a scenario is simulated (``sim``) into a recording; the chain sees only its
``/raw/`` topics and the model vehicle file; what the chain produced is then compared here
with the truth of the same drive.

* ``paper_chain``     one simulated drive through the real chain (``chain_run``)
* ``paper_tasks``     the paper's experiments, one task each (identification, left turn,
                      rollover, false alarms, Table 2 SNR, Table 3 weighting: ``table3_task``)
* ``paper_run``       ``vdps paper``: the tasks over seeds and profiles in a process pool
* ``paper_report``    the paper's published values beside ours (JSON document, text table)
* ``scoring``         truth at an instant, fusion errors, relative parameter errors, the truth
                      trajectory of a prediction, warning frames against the truth events
* ``workbench_study`` the hidden-effect drives of the model workbench's acceptance study
* ``seeds``           every tuning set's seeds gathered, the held-out rule over all of them
* ``synthetic``       analytic trajectories with their truth and Table-1 sensor streams (tests
                      and benchmarks of the estimator)
* ``truth_init``      the truth-initialised predictor state (tests only)
"""
