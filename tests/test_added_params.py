"""``workbench.added_params``: an added effect's parameter on or near a bound of its physical range
is "at bound" (never identified, no sigma), one the fit does not fit is "held", one its descent
never moved "at start", the rest "fitted"; the text names each, and the ten parameters the fit
moved by more than 1 %."""

from __future__ import annotations

import pytest

from vdps_hil.model.effects import make_effect
from vdps_hil.workbench.added_params import (BOUND_MARGIN, IDENTIFIED_KEY, added_parameter_lines, at_bound, not_fitted,
                                              parameter_entries)


def _mf(mu: float):
    return make_effect("magic_formula_tire", peak_friction=mu)


@pytest.mark.parametrize("mu, status, side", [
    (1.6, "at bound", "upper"),  # clipped onto the bound (CommonRoad set 1's circle ramp, --add)
    (1.6 - 0.99 * BOUND_MARGIN * 1.5, "at bound", "upper"),  # within 2 % of the 0.1-1.6 range
    (1.6 - 1.01 * BOUND_MARGIN * 1.5, "fitted", None),
    (1.05, "fitted", None),
    (0.1 + 0.5 * BOUND_MARGIN * 1.5, "at bound", "lower"),
])
def test_a_value_near_a_bound_is_at_bound_and_loses_its_sigma(mu, status, side):
    d = parameter_entries(_mf(mu), {"peak_friction": 0.003})
    p = d["peak_friction"]
    assert (p["status"], p["bound"]) == (status, side)
    assert p["value"] == pytest.approx(mu) and (p["lower"], p["upper"]) == (0.1, 1.6)
    assert p["sigma"] == (None if status == "at bound" else 0.003)
    # the shape and curvature factors were not fitted: held at the generic prior, no sigma
    assert all(d[k]["status"] == "held" and d[k]["sigma"] is None
               for k in ("shape_lateral", "curvature_lateral", "load_sensitivity"))


def test_zero_drag_on_a_drive_without_it_is_at_the_lower_bound():
    d = parameter_entries(make_effect("aero_drag", cda_m2=0.0), {"cda_m2": 0.01})
    assert d["cda_m2"]["status"] == "at bound" and d["cda_m2"]["bound"] == "lower"
    assert d["air_density_kgpm3"]["status"] == "held"


def test_the_text_never_gives_a_bound_value_a_sigma_and_names_the_moved_parameters():
    params = {"magic_formula_tire": parameter_entries(_mf(1.6), {"peak_friction": 0.0027}),
              "aero_drag": parameter_entries(make_effect("aero_drag", cda_m2=0.71), {"cda_m2": 0.012}),
              IDENTIFIED_KEY: {"cornering_stiffness_front_nprad": {"before": 163722.1, "after": 189359.2},
                               "mass_kg": {"before": 1202.8, "after": 1199.6},  # -0.27 %: not listed
                               "inertia_z_kgm2": {"before": 2000.5, "after": 2000.5}}}
    assert at_bound(params) == [("magic_formula_tire", "peak_friction")]
    lines = added_parameter_lines(params, {"magic_formula_tire": "tire saturation"})
    text = "\n".join(lines)
    mu = next(ln for ln in lines if "peak_friction" in ln)
    assert "AT BOUND -- 1.6, the upper bound of 0.1-1.6: not identified" in mu and "+-" not in mu
    assert "  cda_m2: fitted 0.71 +- 0.012 m^2" in lines
    assert lines[0] == "added tire saturation (magic_formula_tire):"
    assert "held at the generic prior: shape_lateral 1.3" in text
    moved = lines[-1]
    assert moved == "re-identified with them (changes above 1 %): front cornering stiffness 163.7 -> 189.4 kN/rad (+16 %)"


def test_a_value_no_step_of_the_fit_moved_is_at_start_without_a_sigma():
    """``at_start`` (``FittedModel.at_start``): the fit's descent kept no step, so the value is
    still the generic prior; an interior value is then "at start", never "fitted" with the
    curvature's sigma; a bound and the held factors keep their own status."""
    d = parameter_entries(_mf(1.0), {"peak_friction": 0.0028}, at_start=True)
    assert d["peak_friction"]["status"] == "at start" and d["peak_friction"]["sigma"] is None
    assert d["shape_lateral"]["status"] == "held"
    assert parameter_entries(_mf(1.6), {"peak_friction": 0.0028}, at_start=True)["peak_friction"]["status"] == "at bound"
    params = {"magic_formula_tire": d}
    assert not_fitted(params) == [("magic_formula_tire", "peak_friction")] and at_bound(params) == []
    mu = next(ln for ln in added_parameter_lines(params) if "peak_friction" in ln)
    assert mu.startswith("  peak_friction: AT START -- 1, the generic prior: no step of the fit") and "+-" not in mu
