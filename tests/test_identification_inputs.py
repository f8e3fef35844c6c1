"""IdentInputs check their shapes and the integer time stamp."""

import dataclasses

import numpy as np
import pytest

from ident_forward import forward


def test_ident_inputs_validate_shapes():
    inp = forward(np.random.default_rng(0), 0)
    with pytest.raises(ValueError, match="slip_ratio"):
        dataclasses.replace(inp, slip_ratio=(0.0, 0.0))
    with pytest.raises(TypeError, match="t_ns"):
        dataclasses.replace(inp, t_ns=0.5)
