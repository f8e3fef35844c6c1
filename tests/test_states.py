"""Named states and the configurable layout: order of eq 7, shape checks, eq-4 expansion of the
derived psi_v (Jacobian against central differences, tolerance 1e-7)."""

import math

import numpy as np
import pytest

from vdps_hil.estimation.states import N_FULL, STATE_NAMES, States, StateLayout
from vdps_hil.model import frames as fr


def test_state_order_is_eq7():
    assert [s.name for s in States] == ["X_G", "Y_G", "Z_G", "XDOT_G", "YDOT_G", "ZDOT_G", "PHI_G", "THETA_G",
                                        "PSI_G", "PHI_R", "THETA_R", "PSI_V"]
    assert len(STATE_NAMES) == N_FULL == 12
    assert STATE_NAMES[States.THETA_R] == "theta_r_rad"


def test_layouts():
    assert StateLayout.paper().n == 12 and StateLayout.paper().is_full
    corrected = StateLayout(road_estimated=True, psi_v_state=False)
    assert corrected.n == 11 and corrected.index(States.PSI_V) is None
    assert corrected.index(States.THETA_R) == 10
    no_road = StateLayout(road_estimated=False)
    assert no_road.n == 9 and no_road.index(States.PHI_R) is None
    assert no_road.names[-1] == "psi_g_rad"
    with pytest.raises(ValueError):
        StateLayout(road_estimated=False, psi_v_state=True)


@pytest.mark.parametrize("bad", [np.zeros(10), np.zeros((11, 1)), np.zeros((1, 11)), np.zeros(12)])
def test_wrong_state_shapes_rejected(bad):
    with pytest.raises(ValueError, match="1-D of length 11"):
        StateLayout().check_x(bad)


@pytest.mark.parametrize("bad", [np.zeros(11), np.zeros((11, 12)), np.zeros((12, 12))])
def test_wrong_covariance_shapes_rejected(bad):
    with pytest.raises(ValueError, match="2-D of shape"):
        StateLayout().check_p(bad)


def test_expand_derives_psi_v_from_eq4(rng):
    lay = StateLayout()
    for _ in range(20):
        x = rng.normal(size=11) * 0.2
        x[8] = rng.uniform(-math.pi, math.pi)
        xf, e = lay.expand(x)
        _, _, psi_v = fr.decompose_vehicle(*xf[6:11])
        assert abs(xf[States.PSI_V] - psi_v) < 1e-12
        # Jacobian of the expansion by central differences
        h = 1e-6
        num = np.empty((12, 11))
        for i in range(11):
            d = np.zeros(11)
            d[i] = h
            num[:, i] = (lay.expand(x + d, False)[0] - lay.expand(x - d, False)[0]) / (2 * h)
        np.testing.assert_allclose(e, num, atol=1e-7)


def test_no_road_layout_fixes_road_and_psi_v_equals_psi_g(rng):
    lay = StateLayout(road_estimated=False)
    x = rng.normal(size=9)
    p = np.diag(rng.uniform(0.1, 1.0, 9))
    xf, pf = lay.full_covariance(x, p)
    assert xf[States.PHI_R] == 0.0 and xf[States.THETA_R] == 0.0
    assert abs(xf[States.PSI_V] - x[8]) < 1e-12
    assert pf[States.PHI_R, States.PHI_R] == 0.0
    assert abs(pf[States.PSI_V, States.PSI_V] - p[8, 8]) < 1e-12


def test_from_full_round_trip(rng):
    lay = StateLayout()
    xf = rng.normal(size=12)
    np.testing.assert_array_equal(lay.from_full(xf), xf[:11])
    with pytest.raises(ValueError):
        lay.from_full(np.zeros(11))
