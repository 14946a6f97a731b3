"""The search and the evidence: how :func:`..diagnose.diagnose` finds and weighs a candidate.

A pass of diagnose is a chain of module-level stages, each handing a small frozen state on
(:mod:`.state`; :func:`.passes.one_pass`):

- ``deviations``: the paired peaks, the mesh's own error folded into their deviations
- ``nominal_check``: the nominal model's global fit (``nominal``), stored, and checked
- ``locate``: which modes carry the misfit, where, and the candidates' scans
- ``rank``: every candidate fitted jointly with the constants, ranked
- ``refit``: the nominal fit improved, a rejected refit searched again, pairs
- ``conclude``: the verdict, its ties and notes: the :class:`~.result.Diagnosis`
- ``passes``: a pass per assignment of the peaks (``reassign``)

``options`` holds every setting (:class:`~.options.DiagnoseOptions`). The tools the stages
use: ``joint_fit`` (a joint problem and its fit), ``laplace`` (the fit's Laplace summary: its
covariance and evidence), ``local_fits`` (local fits from many starts), ``settling`` (rounds
of reduced models checked by the full one), ``tight_finish`` (the last steps of a fit),
``constants_again`` (a candidate's constants searched again globally), ``phases`` (a phase
of the ranking over the candidates), ``two_effects`` (the pairs' stage), ``mesh_error``,
``probabilities``, ``verdict`` (the checks and the verdict), ``separation`` (the
measurement that would tell two apart), ``reassign`` and ``store`` (resume after a kill).
"""
