"""The model workbench (issue 9): compare the model with a drive, see where it fails, learn which
physical effect is missing, add it and watch the error fall.

Data flow: a recording (its ``/raw/`` topics only) and a model vehicle file become one
time-aligned table in ``dataset`` (the samples decoded and collected per kind in ``streams``,
the estimator run over them in ``estimator_run``, IMU measurement effects optionally taken out
first in ``imu_effects``); ``residuals`` evaluates every equation of eq 13 against the paper's
reduced model on that table (one row at a time in ``row_model``), ``innovations`` integrates the
IMU open loop against every GNSS measurement and ``simulation_errors`` runs the predictor from
the estimate over 0.5, 1 and 2 s; ``regimes`` finds the worst windows and bins the residuals over
the operating regime; the effect candidates (``candidates`` picks the adapter per effect from
``candidate_base`` and ``builtin_candidates``) offer their columns to the ranking stages in
``ranking`` -- whitened rows without the estimator's errors (``context``), the design matrix
(``gram``, ``design``), the identification of the ten parameters and of each candidate
(``identification``), forward selection on held-out data (``selection``), equivalence groups
(``equivalence``) and the result with its words (``results``, ``words``); ``add`` re-identifies
with the chosen effects and measures before/after on held-out time; ``model_file`` saves and
loads the model and ``report`` writes one self-contained HTML page (its figures: ``report_figures``). ``diagnosis`` ties the steps
together (``vdps diagnose``); ``user_effects`` loads the user's own effect classes from a named
file or entry point. (The hidden-effect acceptance drives are ``experiments.workbench_study``.)
"""

__all__ = ["Diagnosis", "diagnose"]


def __getattr__(name: str):
    """``Diagnosis`` and ``diagnose`` on first use (PEP 562): importing a submodule such as
    ``model_file`` (``vdps replay --model``, ``vdps bench --model``) does not import the whole
    diagnosis and scipy with it (~1-3 s)."""
    if name in __all__:
        from vdps_hil.workbench import diagnosis

        return getattr(diagnosis, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
