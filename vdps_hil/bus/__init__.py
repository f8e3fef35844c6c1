"""The bus: the plumbing every layer shares, from the devices to the Figure 2 node. Adapters
stamp what a device gives with a clock (``clocks``: live monotonic or a recording's own time),
publish it as raw events (``raw``: CAN frames, serial chunks) and as decoded samples
(``samples``: one catalogue of SI field names, ``t_ns``), and fan it out through bounded
queues (``subscription``) to the recorder, the estimator pipeline and the bench; the
recording keeps both, the pipeline reads only samples."""
from vdps_hil.bus.samples import Sample, FIELDS, FieldSpec, field_spec, check_fields  # noqa: F401
