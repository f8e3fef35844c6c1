"""RowQuantities, the packed per-row named quantities of the workbench's residuals: each row
reads back as the dict appended (exact: float64 values), rows with other names or non-float
values are kept as they were, and an empty one is falsy (the residuals' "no quantities" case)."""

from __future__ import annotations

import math

from vdps_hil.workbench.row_model import RowQuantities


def test_rows_read_back_exactly_in_order():
    q = RowQuantities()
    rows = [{"slip_angle_rad_1": 0.1 * j + 1e-17, "slip_ratio_1": -j / 3.0, "v_mps": math.pi * j} for j in range(50)]
    for r in rows:
        q.append(r)
    assert len(q) == 50 and bool(q)
    assert [q[j] for j in range(50)] == rows  # bit-exact floats, names in order
    assert list(q) == rows
    assert list(q[7]) == ["slip_angle_rad_1", "slip_ratio_1", "v_mps"]


def test_a_row_with_other_names_or_values_is_kept_as_its_dict():
    q = RowQuantities()
    q.append({"a": 1.0, "b": 2.0})
    q.append({"a": 1.0})  # other names
    q.append({"a": 3, "b": 4.0})  # an int, not a float
    q.append({"a": float("nan"), "b": float("inf")})
    assert q[1] == {"a": 1.0}
    assert q[2] == {"a": 3, "b": 4.0} and type(q[2]["a"]) is int
    assert math.isnan(q[3]["a"]) and q[3]["b"] == math.inf
    assert q[0] == {"a": 1.0, "b": 2.0}


def test_a_returned_row_is_a_copy():
    q = RowQuantities()
    q.append({"a": 1.0})
    r = q[0]
    r["a"] = 5.0
    assert q[0] == {"a": 1.0}


def test_empty_is_falsy():
    q = RowQuantities()
    assert not q and len(q) == 0 and list(q) == []


def test_numpy_float64_rows_are_packed_and_read_back_with_the_same_bits():
    """The residuals compute their quantities as numpy float64 (a float subclass): those rows are
    the ones packing exists for."""
    import numpy as np

    q = RowQuantities()
    rows = [{"a": np.float64(0.1) * j, "b": np.float64(-1.0) / (j + 3)} for j in range(20)]
    for r in rows:
        q.append(r)
    assert q.packed == 20
    assert [q[j] for j in range(20)] == rows
    assert all(float(q[j][k]).hex() == float(rows[j][k]).hex() for j in range(20) for k in "ab")
    q.append({"a": np.float32(1.5), "b": 1.0})  # float32 is not a float: kept as its dict
    assert q.packed == 20 and type(q[20]["a"]) is np.float32
