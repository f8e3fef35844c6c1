"""Bus samples, the field catalogue, clocks and time-ordered publish/subscribe."""
from vdps_hil.bus.samples import Sample, FIELDS, FieldSpec, field_spec, check_fields  # noqa: F401
