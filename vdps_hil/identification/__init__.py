"""Online identification of the ten vehicle parameters (paper section 5, eq 18-23).

Data flow: the estimator's outputs (``Estimate``, ``FilteredSignals``) -> ``feeder.IdentFeeder``
-> ``inputs.IdentInputs`` (estimated quantities in the aux frame, never simulator truth) ->
``identifier.Identifier``, which builds each problem's regressor (``problems``, eq 20-23, with
the spring, tire and moment models of ``forces``) and updates its weighted RLS (``rls``, eq 19)
in the order mass, tracking, cornering, inertia (settings and the problem table: ``config``) ->
identified parameters with sigmas (a new frozen ``IdentifiedParams``), saved between drives by
``persistence``; ``observability_report`` says what a drive identified and why not. The
misprints of the paper found here are listed in the ``problems`` and ``rls`` docstrings.
"""

from vdps_hil.identification.config import (PROBLEM_NAMES, PROBLEM_PARAMS, IdentConfig, IdentConfigError,
                                            load_ident_config, parse_ident_config)
from vdps_hil.identification.identifier import Identifier
from vdps_hil.identification.inputs import IdentInputs, gravity_aux_mps2
from vdps_hil.identification.persistence import (ParamsFileError, PersistedParams, load_params,
                                                 reset_params, save_params)
from vdps_hil.identification.problems import REGRESSORS, Regressor, balanced_weighting
from vdps_hil.identification.rls import RLSCounters, WeightedRLS

__all__ = [
    "IdentConfig", "IdentConfigError", "IdentInputs", "Identifier", "PROBLEM_NAMES", "PROBLEM_PARAMS",
    "REGRESSORS", "ParamsFileError", "PersistedParams", "RLSCounters", "Regressor", "WeightedRLS",
    "balanced_weighting", "gravity_aux_mps2", "load_ident_config", "load_params", "parse_ident_config",
    "reset_params", "save_params",
]
