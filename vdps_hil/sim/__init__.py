"""Simulation: scenarios, the truth simulator, the driver model and the rollover definitions.

* :mod:`.scenarios` -- ``load_scenario(name)`` reads ``configs/scenarios/<name>.toml``.
* :mod:`.simulator` -- ``Simulator(scenario=...)``: ``step_to(t)``, ``kinematics()``,
  ``set_input_override(...)``, ``truth`` (100 Hz snapshots).
* :mod:`.truth_cr` -- ``CommonRoadTruth(set_id, scenario)``: CommonRoad's multibody model as a
  second truth with the same interface (``vdps sim --truth commonroad-mb:1``; :mod:`.cr_model`,
  :mod:`.cr_inputs`, registry :mod:`.truth_backends`, shared clock :mod:`.stepping`).
* :mod:`.driver` -- pure-pursuit path following and PI speed control.
* :mod:`.rollover` -- tip-up and point of no return, defined once.

``sim`` never imports ``estimation``; the pipeline never imports ``sim``.
"""
