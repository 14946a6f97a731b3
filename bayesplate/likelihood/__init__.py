"""The Gaussian problem and its inputs: what the estimators, the sampler and diagnose share.

``posterior`` (``GaussianProblem.from_case``: the prior, the data and their covariances),
``inputs`` (the measured inputs' uncertainty: their Jacobian, the variance budget, the
marginal covariance), ``inputs_posterior`` (the inputs' posterior, one conditional draw per
kept draw of the constants), ``input_summary`` (its mean, sd and interval) and
``error_scale`` (an unknown common scale of the frequency deviations: its prior, the
Student-t marginal likelihood, draws of ``s``).
"""
