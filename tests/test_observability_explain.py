"""The filter's null spaces are explained (and the explanation does not depend on which basis of
the null space the SVD returns), and the generic rank of a sensor set."""

from __future__ import annotations

import numpy as np

from vdps_hil.estimation.ekf_config import EkfConfig, SensorSet
from vdps_hil.estimation.observability import observability_rank
from vdps_hil.estimation.observability_explain import explain_null_space, structural_report
from vdps_hil.model.params import load_vehicle

VEH = load_vehicle("sedan-model")
NAMES = ("a", "b", "c", "d")


def _null(o):
    return observability_rank([o], NAMES[: o.shape[1]]).null_space


def test_explanations_of_known_null_spaces():
    e = explain_null_space(_null(np.array([[1.0, -1.0, 0.0], [0.0, 0.0, 1.0]])), NAMES[:3])
    assert [(x.kind, x.names) for x in e] == [("only_difference", ("a", "b"))]
    assert e[0].text == "a, b: only their difference is observable"
    e = explain_null_space(_null(np.array([[1.0, 1.0, 0.0], [0.0, 0.0, 1.0]])), NAMES[:3])
    assert [(x.kind, x.names) for x in e] == [("only_sum", ("a", "b"))]
    e = explain_null_space(_null(np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])), NAMES[:3])
    assert [(x.kind, x.names) for x in e] == [("not_observable", ("c",))]
    e = explain_null_space(_null(np.array([[1.0, 2.0, 0.0], [0.0, 0.0, 1.0]])), NAMES[:3])
    assert e[0].kind == "combination" and e[0].names == ("a", "b")
    assert np.allclose(e[0].coefficients, (1.0, -0.5))  # moving a by 1 and b by -1/2 changes nothing
    assert explain_null_space(np.zeros((0, 3)), NAMES[:3]) == []


def test_explanation_does_not_depend_on_the_null_space_basis(rng):
    """Null space = span{e_d, (e_a - e_b)/sqrt 2}: any orthonormal basis of it (rotated at random)
    gives 'd not observable' and 'a, b only their sum'... of the same two statements."""
    base = np.array([[0.0, 0.0, 0.0, 1.0], [1.0, -1.0, 0.0, 0.0]])
    base[1] /= np.sqrt(2.0)
    for _ in range(20):
        q, _ = np.linalg.qr(rng.normal(size=(2, 2)))
        e = explain_null_space(q @ base, NAMES)
        assert sorted((x.kind, x.names) for x in e) == [("not_observable", ("d",)), ("only_sum", ("a", "b"))]


def test_generic_rank_of_sensor_sets():
    full = structural_report(EkfConfig(), VEH.mounting.gnss_lever_arm_m)
    assert (full.rank, full.n_states, full.unobservable) == (11, 11, ())
    ns = structural_report(EkfConfig(sensors=SensorSet(suspension=False)), VEH.mounting.gnss_lever_arm_m)
    assert ns.rank == 9 and set(ns.unobservable) == {"phi_r_rad", "theta_r_rad"}
    texts = " | ".join(e.text for e in (*ns.not_estimated, *ns.explanations))
    print("\nno suspension travel:", texts)
    assert "phi_r, theta_r: not estimated" in texts and "no measurement kind of this sensor set" in texts
    assert {e.names[0] for e in ns.not_estimated if e.kind == "derived"} == {"phi_v", "theta_v"}
    ng = structural_report(EkfConfig(sensors=SensorSet(gnss="none")), VEH.mounting.gnss_lever_arm_m)
    assert {"x_g_m", "y_g_m", "z_g_m"} <= set(ng.unobservable) and ng.rank < 11
    # the same seed gives the same analysis
    assert structural_report(EkfConfig(), seed=3).report.singular_values == \
        structural_report(EkfConfig(), seed=3).report.singular_values
