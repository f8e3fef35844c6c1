"""Named states and the configurable layout: order of eq 7, shape checks, eq-4 expansion of the
derived psi_v (Jacobian against central differences, tolerance 1e-7)."""

import math

import numpy as np
import pytest

from vdps_hil.estimation.states import ALL_STATE_NAMES, N_EXT, N_FULL, STATE_NAMES, AugStates, States, StateLayout
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


def test_augmented_layout_bias_and_wheel_scale_states(rng):
    """Bias and wheel-scale states follow the eq-7 states; names, indices, padding of a 12-vector
    and the N_EXT expansion (E rows of the augmented states are unit rows, E of eq 7 unchanged)."""
    lay = StateLayout(road_estimated=False, gyro_bias_axes=(2,), accel_bias_axes=(0, 1), wheel_scale=True)
    assert lay.n == 13 and lay.n_kinematic == 9 and lay.augmented
    assert lay.names[9:] == ("gyro_bias_z_radps", "accel_bias_x_mps2", "accel_bias_y_mps2", "wheel_speed_scale")
    assert lay.index(AugStates.BG_Z) == 9 and lay.index(AugStates.BG_X) is None
    assert lay.index(AugStates.WHEEL_SCALE) == 12 and lay.states[-1] is AugStates.WHEEL_SCALE
    assert len(ALL_STATE_NAMES) == N_EXT == 19
    xf = rng.normal(size=12)
    x = lay.from_full(xf)
    np.testing.assert_array_equal(x[:9], xf[:9])
    np.testing.assert_array_equal(x[9:], 0.0)
    x[9:] = [0.01, 0.2, -0.1, 0.02]
    xe, e = lay.expand(x, ext=True)
    assert xe.shape == (N_EXT,) and e.shape == (N_EXT, 13)
    assert xe[AugStates.BG_Z] == 0.01 and xe[AugStates.BA_Y] == -0.1 and xe[AugStates.BG_X] == 0.0
    np.testing.assert_array_equal(e[AugStates.WHEEL_SCALE], np.eye(13)[12])
    x12, e12 = lay.expand(x)
    assert x12.shape == (12,) and e12.shape == (12, 13) and not e12[:, 9:].any()
    np.testing.assert_array_equal(lay.from_full(xe), x)
    vals = lay.augmented_values(x, np.eye(13) * 4.0)
    assert vals["accel_bias_x_mps2"] == (0.2, 2.0)
    with pytest.raises(ValueError, match="gyro_bias_axes"):
        StateLayout(gyro_bias_axes=(3,))
    with pytest.raises(ValueError, match="accel_bias_axes"):
        StateLayout(accel_bias_axes=(1, 0))
    assert not StateLayout().augmented and StateLayout().n_kinematic == 11
