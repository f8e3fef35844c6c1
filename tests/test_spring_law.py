"""The spring law of eq 14 per corner (``model.spring_law``)."""

import numpy as np

from ident_forward import MODEL
from vdps_hil.model.spring_law import suspension_forces_n


def test_eq14_floor_on_extension():
    # wheel hanging: the spring extended past its free length; K H + m_u g is floored at zero
    f = suspension_forces_n(MODEL, np.full(4, -0.5), np.zeros(4))
    assert np.allclose(f, 0.0, atol=1e-9)


def _reference(vehicle, defl, rate, weight=True):
    """Eq 14 per corner written out from the vehicle file (no cache)."""
    out = []
    for i in range(4):
        ax = vehicle.axle(i)
        h = ax.static_compression_m + defl[i]
        f = ax.spring_c1_npm * np.exp(ax.spring_c2_per_m * (h - ax.spring_c3_m)) * h
        if not weight:
            out.append(f + ax.damper_nspm * rate[i])
            continue
        mug = ax.unsprung_mass_kg * 9.80665
        out.append(0.0 if f + mug <= 0.0 else max(f + ax.damper_nspm * rate[i] + mug, 0.0))
    return np.array(out)


def test_repeated_calls_return_fresh_copies_of_the_same_forces():
    # the identifier asks for the same corners several times per input: the kept result must be
    # the law's value every time, and a caller changing its copy must not change the next one
    defl, rate = (0.011, 0.009, 0.012, 0.008), (0.02, -0.01, 0.0, 0.005)
    for weight in (True, False):
        first = suspension_forces_n(MODEL, defl, rate, include_unsprung_weight=weight)
        first[:] = -1.0
        again = suspension_forces_n(MODEL, defl, rate, include_unsprung_weight=weight)
        np.testing.assert_allclose(again, _reference(MODEL, defl, rate, weight), rtol=1e-12)
        assert again.tolist() == suspension_forces_n(MODEL, np.array(defl), np.array(rate), weight).tolist()


def test_another_vehicle_with_the_same_deflections_gets_its_own_forces():
    # results are kept by the vehicle's identity: a stiffer copy of the file must not read the
    # first vehicle's forces for the same deflection tuple
    import dataclasses

    stiff = dataclasses.replace(MODEL, front=dataclasses.replace(MODEL.front, spring_c1_npm=2.0 * MODEL.front.spring_c1_npm))
    defl, rate = (0.02, 0.02, 0.02, 0.02), (0.0,) * 4
    soft_f = suspension_forces_n(MODEL, defl, rate)
    stiff_f = suspension_forces_n(stiff, defl, rate)
    np.testing.assert_allclose(stiff_f, _reference(stiff, defl, rate), rtol=1e-12)
    assert stiff_f[0] > soft_f[0] + 1000.0 and stiff_f[2] == soft_f[2]
    assert suspension_forces_n(MODEL, defl, rate).tolist() == soft_f.tolist()
