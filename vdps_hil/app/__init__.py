"""The applications around the Figure 2 node: processes and files. ``replay`` reads a
recording's ``/raw/`` topics (decoded here or in a second process, ``replay_io``), sizes the
node (``pipeline.node.VdpsSystem``) from the sensors it finds, feeds it and writes what it
returns to an output recording (``est_topics``: the ``/est/`` layout) and a summary
(``replay_summary``: the ``--json`` document); ``session`` is the live recording session of
``vdps log`` and the bench (adapters -> bus -> ``record.recorder``). Below it: the node and
everything it is built of; above it: the bench, the batch engine and the CLI."""
