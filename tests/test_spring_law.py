"""The spring law of eq 14 per corner (``model.spring_law``)."""

import numpy as np

from ident_forward import MODEL
from vdps_hil.model.spring_law import suspension_forces_n


def test_eq14_floor_on_extension():
    # wheel hanging: the spring extended past its free length; K H + m_u g is floored at zero
    f = suspension_forces_n(MODEL, np.full(4, -0.5), np.zeros(4))
    assert np.allclose(f, 0.0, atol=1e-9)
