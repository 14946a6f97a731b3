"""The search and the evidence: how :func:`..diagnose.diagnose` finds and weighs a candidate.

``nominal`` (the nominal model's global fit), ``mesh_error``, ``rank`` (every candidate
fitted jointly with the constants, ranked), ``two_effects`` (the pairs' stage),
``reassign`` (the assignment made again), ``verdict``, ``separation``, ``probabilities``;
and the tools they use: ``joint_fit``, ``local_fits``, ``settling``, ``tight_finish``,
``constants_again``, ``store``.
"""
