"""Simulation: scenarios, the truth simulator, the driver model, the sensor models and the drive
writer.

* :mod:`.signals` -- the signals of scenario files (a leaf shared by scenarios and driver).
* :mod:`.scenarios` -- ``load_scenario(name)`` reads ``configs/scenarios/<name>.toml``.
* :mod:`.driver` -- pure-pursuit path following (:class:`~.driver.ReferencePath`) and PI speed control.
* :mod:`.simulator` -- ``Simulator(scenario=...)``: ``step_to(t)``, ``kinematics()``,
  ``set_input_override(...)``, ``truth`` (100 Hz snapshots), on the physics core (``model.core``).
* :mod:`.sampling` -- the per-step truth the sensors read, their sampling instants and random streams.
* :mod:`.sensors` -- IMU, GNSS and chassis sensor models; :mod:`.profiles` their data sheets.
* :mod:`.faults` -- sensor faults; :mod:`.wire` -- the real wire formats and their timing.
* :mod:`.drive` -- ``Drive(scenario).run(out.mcap)``; :mod:`.session` steps it block by block into
  a sink (:mod:`.sinks`: the recording, or the HIL bench's live wires).
* :mod:`.truth_cr` -- ``CommonRoadTruth(set_id, scenario)``: CommonRoad's multibody model as a
  second truth with the same interface (``vdps sim --truth commonroad-mb:1``; :mod:`.cr_model`,
  :mod:`.cr_inputs`, registry :mod:`.truth_backends`, shared clock :mod:`.stepping`).

Rollover (tip-up, point of no return) is defined once in :mod:`vdps_hil.model.rollover`.
``sim`` never imports ``estimation``; the pipeline never imports ``sim``.
"""
