"""The parameters a prediction may use: what the identifier vouches for.

The identifier's current values (``Identifier.params``) are its running estimates, whatever
their status. A prediction, and so the rollover warning, should not rest on a value the
identifier itself does not call identified: a value on its bound, a fit the residual test
rejects, or an estimate the data moved away from a good start and has not settled again
(``identification.status``). ``TrustedParams`` keeps, per parameter::

    the identifier's value      while the parameter's status is "identified"
    the last such value         after it stops being identified
    the start value             before it was ever identified (the run's start parameters:
                                saved ones, ``--params``, or the model file's priors)

re-read every ``period_s`` of input time (the predictor's cadence: one read per prediction at
most, the same instants live and in replay).

Why (issue 17, 2026-12-07): ``vdps paper --quick``'s sine sweep on the ``table1`` profile,
started from a calibration drive's parameters, sent a rollover warning (levels >= 2 from 4.31 to
5.01 s) while the truth's |LTR| stayed below 0.20. During the sweep the cornering problem left
the calibrated values, reached its bounds (rear 54 -> 306 kN/rad, I_z 1053 kg m^2 at its bound)
and wandered "not converged" between them (rear 50-113 kN/rad at 3.75-5.0 s); the predictor
used those values and foresaw a point of no return four times. Predicting from the values last
identified (the calibration's), the run sent no warning; the lane change and the steady circle
were unchanged (no warning either way). Measured with scratch scripts around
``experiments.paper_chain.chain_run``; the sweep is a test both ways in
``tests/test_paper_tasks.py``, the rule itself in ``tests/test_trusted.py``.
"""

from __future__ import annotations

import math

from vdps_hil.model.params import IdentifiedParams

__all__ = ["TrustedParams"]


class TrustedParams:
    """Per parameter the last identified value, else the start value (module docstring).

    ``identifier``: an ``Identifier`` (read only: ``problem_status``); ``start``: the run's start
    parameters; ``period_s``: how often ``at`` re-reads the status (input time). ``source`` says
    per parameter where the value came from: "identified" (read at the last re-read), "held"
    (identified before, not now) or "start"."""

    def __init__(self, identifier, start: IdentifiedParams, period_s: float = 0.1):
        if not (isinstance(period_s, (int, float)) and math.isfinite(period_s) and period_s > 0):
            raise ValueError(f"TrustedParams.period_s must be a positive number, got {period_s!r}")
        self._identifier = identifier
        self._values = dict(start.as_dict())
        self._params = start
        self._period_ns = int(round(period_s * 1e9))
        self._next_ns: int | None = None
        self.source = {name: "start" for name in self._values}

    def at(self, t_ns: int) -> IdentifiedParams:
        """The trusted parameters at input time ``t_ns`` (re-read at the first call of each
        period; the same object between re-reads and while nothing changed)."""
        if self._next_ns is None or t_ns >= self._next_ns:
            self._next_ns = t_ns - t_ns % self._period_ns + self._period_ns
            self.refresh()
        return self._params

    def refresh(self) -> IdentifiedParams:
        """Re-read the identifier's status now."""
        changed = False
        for st in self._identifier.problem_status.values():
            for p in st.params:
                if p.identified:
                    self.source[p.name] = "identified"
                    if self._values[p.name] != p.value:
                        self._values[p.name] = p.value
                        changed = True
                elif self.source[p.name] == "identified":
                    self.source[p.name] = "held"
        if changed:
            self._params = IdentifiedParams(**self._values)
        return self._params
