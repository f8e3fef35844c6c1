"""Chi-square quantile of the EKF's innovation gate: the gate of an update with ``dof`` rows
rejects NIS > chi2_quantile(p_gate, dof) (``ekf`` module docstring).

The default gate probability (``EkfConfig.gate_probability`` = 0.9999, the one every shipped
sensor set uses) reads a table of scipy's ``chi2.ppf(0.9999, dof)`` for dof 1..6 (the update
sizes of ``observations``; tested equal to scipy within 4 ulp), as does the aiding monitor's
0.999 (``GATE_TABLE``); any other probability or size
is scipy's ``scipy.special.chdtri(dof, 1 - p)``, imported then. The table keeps scipy out of the
start-up of every replay, bench and logger process: importing ``scipy.special`` on top of numpy
measured +1.34 s per fresh interpreter on this 2-core machine at load average 17.6 (median of
8 runs, ``python -c "import numpy, scipy.special"`` against ``python -c "import numpy"``).
"""

from __future__ import annotations

__all__ = ["GATE_TABLE", "chi2_quantile"]

GATE_TABLE: dict[float, tuple[float, ...]] = {
    0.9999: (15.136705226623606, 18.420680743952584, 21.107513466160444, 23.512742444991076,
             25.74483195905612, 27.85634123601417),
    0.999: (10.827566170662733, 13.815510557964274, 16.26623619623813, 18.46682695290317,
            20.515005652432873, 22.457744484825323, 24.321886347856854, 26.12448155837614,
            27.877164871256568, 29.58829844507442, 31.264133620239985, 32.90949040736021,
            34.52817897487089, 36.12327368039813, 37.69729821835383, 39.252354790768464,
            40.79021670690253, 42.31239633167996),
}
"""p -> (chi2.ppf(p, 1), ..., chi2.ppf(p, n)), from scipy 1.x: 0.9999 for the innovation gate
(dof 1..6), 0.999 for the aiding monitor's consistency test (``aiding_monitor``: the NIS of the
last updates of one kind summed, dof up to 18)."""


def chi2_quantile(p: float, dof: int) -> float:
    """The ``p`` quantile of the chi-square distribution with integer ``dof`` >= 1 (the
    innovation gate): ``GATE_TABLE``, else ``scipy.special.chdtri(dof, 1 - p)``."""
    if not 0.0 < p < 1.0 or int(dof) != dof or dof < 1:
        raise ValueError(f"chi2_quantile needs 0 < p < 1 and an integer dof >= 1, got p={p!r}, dof={dof!r}")
    row = GATE_TABLE.get(p)
    if row is not None and dof <= len(row):
        return row[int(dof) - 1]
    from scipy.special import chdtri

    return float(chdtri(int(dof), 1.0 - p))
