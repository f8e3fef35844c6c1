"""Hardware-in-the-loop bench: the simulated vehicle on live CAN and serial wires paced to the
wall clock, the live VDPS pipeline answering with VDPS_Warning on CAN, a simulated ECU reacting.

Data flow. :class:`~vdps_hil.hil.bench.Bench` (``bench``, configured by ``bench_config``) runs a
drive on the simulator side (``simside``), which sends its CAN frames and serial read chunks at
their own times, paced by the bench clock (``pacing``), through the wires (``transports``
chooses them: the CAN device sides of ``can_devices``, the pseudo-terminals and device FIFOs of
``serial_device``); the pipeline side (``pipelines``: a ``node.PipelineNode`` in this process or
in the child process ``child``) reads them with the real adapters, feeds ``VdpsSystem`` and
sends its warning frames back on CAN to the simulated ECU (``ecu``), whose braking acts on the
simulator; ``latency`` times warnings against the send logs and the truth events, and the bench
reports what was sent, received, lost and late.

Only ``hil`` and ``cli`` open devices or start threads.
"""
