"""Simulation: scenarios, the truth simulator, the driver model and the rollover definitions.

* :mod:`.scenarios` -- ``load_scenario(name)`` reads ``configs/scenarios/<name>.toml``.
* :mod:`.simulator` -- ``Simulator(scenario=...)``: ``step_to(t)``, ``kinematics()``,
  ``set_input_override(...)``, ``truth`` (100 Hz snapshots).
* :mod:`.driver` -- pure-pursuit path following and PI speed control.
* :mod:`.rollover` -- tip-up and point of no return, defined once.

``sim`` never imports ``estimation``; the pipeline never imports ``sim``.
"""
