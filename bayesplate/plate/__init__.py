"""The plate model: the finite-element model of one plate and what it answers.

``model`` (``PlateModel``: the full finite-element model on the :mod:`bayesplate.fem`
element, mesh and eigen solve), ``modal`` (``ModalResult``: the result of a modal solve),
``forward`` (the ``ForwardModel`` and ``Modes`` protocols that the full, reduced and
certified models implement) and ``plate_bounds`` (the lowest eigenvalue bounded from above
in closed form, Rayleigh-Ritz). The lamina mechanics ``b(e)`` stay at the root in
:mod:`bayesplate.laminate`, beside :mod:`bayesplate.quantities`, which uses them.
"""
