"""What a report computes: :class:`ReportOptions` (mesh, quick look, seed, optional steps)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..plate.model import DEFAULT_MESH

__all__ = ["ReportOptions"]


@dataclass(frozen=True)
class ReportOptions:
    """What the report computes.

    Parameters
    ----------
    quick : bool
        A first look: the working mesh has half the elements each way (unless `mesh` is
        given), diagnose makes one random start instead of four, and the posterior chains
        are shorter. Nothing is skipped.
    mesh : tuple of int, optional
        Elements along x and y; default the case's ``[model] mesh``.
    seed : int
        Seeds diagnose's random starts and the sampler.
    diagnose : bool
        Run the model-discrepancy diagnosis (the longest step).
    sample : bool
        Sample the posterior when :mod:`bayesplate.sampling` is available.
    n_shapes : int
        Mode shapes drawn.
    pairing : {"auto", "mac", "likelihood", "index", "order"}
        Measured-to-computed modes for every step (as :func:`bayesplate.estimators.estimate`
        takes it); ``"likelihood"``: the assignment B settles on, whose unobserved modes and
        spurious peaks the report names.
    """

    quick: bool = False
    mesh: tuple | None = None
    seed: int = 0
    diagnose: bool = True
    sample: bool = True
    n_shapes: int = 6
    pairing: str = "auto"

    def working_mesh(self, case):
        """Elements ``(nx, ny)`` of the working mesh for `case`."""
        if self.mesh is not None:
            return tuple(int(n) for n in self.mesh)
        nx, ny = case.mesh or DEFAULT_MESH
        if self.quick:
            nx, ny = max(math.ceil(nx / 2), 2), max(math.ceil(ny / 2), 1)
        return int(nx), int(ny)

    @property
    def n_starts(self):
        """Random starts of diagnose's nominal fit (besides the prior mean)."""
        return 1 if self.quick else 4
