"""Which effect is missing: the effect candidates ranked by held-out explained fraction, forward
selection, fitted parameters with sigmas, plausibility, excitation and equivalence groups.

The linear model of the residuals (``residuals``: r = measured - model at the identified model)::

    r = N eta + B delta_p + sum_c X_c theta_c + e

N: nuisance -- per row the estimator's body-velocity and slip directions (projected out row by
row) and, for the GNSS innovations, the initial attitude, velocity and position (9 columns);
B: the ten identified parameters (eq 20-23, re-identified with every fit, weak prior
delta_p ~ N(0, (0.5 p)^2) so a parameter the drive does not excite stays where it was);
X_c: the columns of candidate c (``candidates``). Every row is divided by its equation's noise
sigma (inverse noise variance weighting per equation; GNSS rows by their sigma).

The stages, one module each (their docstrings hold their formulas)::

    context         the residual rows whitened, the estimator's errors projected out; the
                    column builders the candidates call
    gram, design    the design matrix: stacked rows, named column blocks with priors, per
                    (micro block, row group) sufficient statistics, MAP fit, blocked
                    cross-validation, effective sample size, sigmas
    identification  the base fit (Gauss-Newton on the MAP objective) and the candidates'
                    joint fits with the ten parameters
    selection       rank(): explained fractions, excitation, forward selection by BIC and
                    evidence thresholds, the final entries
    equivalence     which candidates and parameters a drive cannot tell apart
    results         Ranking and RankEntry, their JSON and words
    config          RankingConfig (the thresholds) and the row groups

Entry point: :func:`vdps_hil.workbench.ranking.selection.rank`.
"""
