"""Online identification of the ten vehicle parameters (paper section 5, eq 18-23).

``rls``: weighted and scaled RLS of eq 19 (forgetting, bounds, gating, sigmas, identifiability).
``problems``: the four problems (mass, tracking stiffness, cornering stiffness, inertia), their
regressors from estimated quantities (``IdentInputs``), the config and the ``Identifier``.
``persistence``: identified parameters saved/loaded between drives (JSON, sanity bounds).
The misprints of the paper found here are listed in the ``problems`` and ``rls`` docstrings.
"""

from vdps_hil.identification.persistence import (ParamsFileError, PersistedParams, load_params,
                                                 reset_params, save_params)
from vdps_hil.identification.problems import (PROBLEM_NAMES, PROBLEM_PARAMS, REGRESSORS, IdentConfig,
                                              IdentConfigError, IdentInputs, Identifier, Regressor,
                                              balanced_weighting, gravity_aux_mps2, load_ident_config,
                                              parse_ident_config)
from vdps_hil.identification.rls import RLSCounters, WeightedRLS

__all__ = [
    "IdentConfig", "IdentConfigError", "IdentInputs", "Identifier", "PROBLEM_NAMES", "PROBLEM_PARAMS",
    "REGRESSORS", "ParamsFileError", "PersistedParams", "RLSCounters", "Regressor", "WeightedRLS",
    "balanced_weighting", "gravity_aux_mps2", "load_ident_config", "load_params", "parse_ident_config",
    "reset_params", "save_params",
]
