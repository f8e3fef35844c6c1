"""Hardware-in-the-loop bench: the simulated vehicle on live CAN and serial wires paced to the
wall clock, the live VDPS pipeline answering with VDPS_Warning on CAN, a simulated ECU reacting.

* :mod:`.transports` -- the wires: python-can virtual bus, slcan on a pty, socketcand on
  127.0.0.1, any python-can interface string; serial through pseudo-terminals.
* :mod:`.pacing` -- the bench clock (simulated time tied to CLOCK_MONOTONIC by ``--speed``),
  absolute deadlines, late sends.
* :mod:`.simside` -- the vehicle's side: a ``sim.drive`` session feeding the wires, the ECU.
* :mod:`.node` -- the pipeline's side: the real adapters, ``VdpsSystem``, warnings back on CAN.
* :mod:`.ecu` -- the simulated ECU: CRC/counter/timeout checks, torque cut and braking.
* :mod:`.latency` -- warning latency and lead time, defined once.
* :mod:`.bench` -- ``Bench(BenchConfig(...)).run()``; :mod:`.child` the pipeline process.

Only ``hil`` and ``cli`` open devices or start threads.
"""
