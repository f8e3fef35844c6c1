"""The report's figures (``workbench.report_figures``): vector, reproducible, the effect law's
plot and its data helpers. The law on a real diagnosis (drag against speed follows
-1/2 rho C_d A v^2): ``tests/test_report.py``."""

from __future__ import annotations

import base64
import re

import numpy as np
import pytest

from vdps_hil.model.effects import REGISTRY
from vdps_hil.workbench import report_figures as F
from vdps_hil.workbench.regimes import REGIME_LABELS


def _svg(uri: str) -> str:
    head = "data:image/svg+xml;base64,"
    assert uri.startswith(head)
    return base64.b64decode(uri[len(head):]).decode("utf-8")


def _law(n: int = 400, seed: int = 5) -> F.EffectLaw:
    rng = np.random.default_rng(seed)
    v = rng.uniform(10.0, 35.0, n)
    term = -0.42 * v ** 2
    return F.EffectLaw("aero_drag", "long", "speed_mps", "speed [m/s]", v, term + rng.normal(0.0, 5.0, n), term, 0.99)


def test_every_effect_regressor_is_a_registered_effect_and_a_known_quantity():
    for eff, q in F.EFFECT_REGRESSOR.items():
        assert eff in REGISTRY, eff
        assert q in REGIME_LABELS or q in ("heading_deg", "yaw_rate_degps", "t_s"), (eff, q)


def test_figures_are_vector_and_the_same_figure_gives_the_same_bytes():
    a = _svg(F.figure_svg(F.fig_effect_law(_law())))
    b = _svg(F.figure_svg(F.fig_effect_law(_law())))
    assert a == b  # fixed ids, no date: the same diagnosis renders the same page
    assert a.lstrip().startswith("<?xml") and "<svg" in a and "<path" in a
    assert "<text" in a and "speed [m/s]" in a  # text kept as text (searchable, sharp when zoomed)
    assert "<image" not in a  # no raster inside
    # nothing to fetch: links only inside the file (XML namespace names are not fetched)
    assert not re.search(r'(href|src)\s*=\s*"(?!#|data:)', a)


def test_bin_means_follow_the_law_they_are_given():
    """Quantile bins of y = -0.42 x^2 without noise: each bin mean lies on the curve within the
    curvature bias of its bin (x spread <= 2.5 m/s in a bin: bias <= 0.42 * 2.5^2 / 12 ~ 0.22)."""
    x = np.linspace(10.0, 35.0, 1200)
    bx, by = F._bin_means(x, -0.42 * x ** 2)
    assert len(bx) == 12 and np.all(np.diff(bx) > 0)
    assert np.max(np.abs(by - (-0.42 * bx ** 2))) < 0.25
    # non-finite rows are left out; a constant x gives no bins instead of dividing by zero
    y = -0.42 * x ** 2
    y[::7] = np.nan
    assert len(F._bin_means(x, y)[0]) == 12
    assert len(F._bin_means(np.full(50, 3.0), np.ones(50))[0]) == 0


def test_the_law_plot_draws_points_bin_means_and_the_law_with_the_explained_share():
    fig = F.fig_effect_law(_law())
    ax = fig.axes[0]
    labels = [ln.get_label() for ln in ax.get_lines()]
    assert any("fitted law" in s for s in labels) and any("bin means" in s for s in labels)
    law_line = next(ln for ln in ax.get_lines() if "fitted law" in ln.get_label())
    xs, ys = law_line.get_data()
    np.testing.assert_allclose(ys, -0.42 * np.asarray(xs) ** 2, rtol=0.02)
    assert "99 %" in ax.get_title() and ax.get_xlabel() == "speed [m/s]"
    assert "longitudinal force residual [N]" == ax.get_ylabel()
    F._plt().close(fig)


@pytest.mark.parametrize("n", [F.MAX_POINTS * 3 + 1, 10])
def test_time_series_are_thinned_to_at_most_max_points(n):
    assert len(np.arange(n)[F._thin(n)]) <= F.MAX_POINTS
    assert len(np.arange(n)[F._thin(n)]) >= min(n, F.MAX_POINTS // 2)
