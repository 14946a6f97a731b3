"""Bit-for-bit fingerprint of the reduced-basis model (issue 11: the reduced split).

Builds the certified fast model of the bundled case plate1 on its 8 x 4 mesh the way
tests/test_reduced.py does, evaluates it at five fixed points of the box and records the
certificate; also a reduced model with a stiffness independent of ``b`` (elastic foundation).
Prints the sha256 of all their bytes: it must not change when the code is only moved.

Run: ``python -m studies.reduced_fingerprint``.
"""

import hashlib

import numpy as np

from bayesplate.discrepancy.physics.elastic_foundation import ElasticFoundation
from bayesplate.io import bundled_case_path, load_case
from bayesplate.plate.model import PlateModel
from bayesplate.reduced import ReducedModel, fast_model, prior_stiffness, stiffness_box

N_MODES, SEED = 14, 20070461
FRACTIONS = (0.5, 0.1, 0.9, 0.25, 0.75)


def main():
    """Print the digests of the fast model, its certificate and the foundation model."""
    case = load_case(bundled_case_path("plate1"))
    model = PlateModel.from_case(case, mesh=(8, 4))
    mean_b, _ = prior_stiffness(case.prior)
    box = stiffness_box(case.prior)
    fast = fast_model(model, mean_b, box, N_MODES, rng=SEED)
    points = [box.lower + t * (box.upper - box.lower) for t in FRACTIONS]
    points[3] = points[3].copy()
    points[3][2] = box.upper[2] - 0.3 * (box.upper[2] - box.lower[2])  # not on the diagonal
    h_eval, h_cert, h_found = hashlib.sha256(), hashlib.sha256(), hashlib.sha256()
    for b in points:
        r = fast.solve(b, N_MODES)
        h_eval.update(np.ascontiguousarray(r.eigenvalues).tobytes())
        h_eval.update(np.ascontiguousarray(r.sensitivities).tobytes())
        h_eval.update(np.ascontiguousarray(fast.eigenvalues(b, N_MODES)).tobytes())
    for c in fast.history:
        for x in (c.max_rel_error, c.per_mode_max, c.errors, c.points, c.tolerance):
            h_cert.update(np.ascontiguousarray(x, dtype=float).tobytes())
        h_cert.update(repr((c.n_test, c.passed, c.basis_size, c.n_probe, str(c))).encode())
    h_cert.update(np.ascontiguousarray(fast.reduced.basis).tobytes())
    h_cert.update(np.ascontiguousarray(fast.reduced.terms).tobytes())
    h_cert.update(repr((fast.reduced.levels, fast.reduced.block_sizes)).encode())
    physics = ElasticFoundation()
    (k,) = physics.parameters(model, mean_b)
    supported = physics.apply(model, (10 * k.sd,))
    red = ReducedModel.build(supported, mean_b, box, N_MODES, n_snapshots=2, rank_tol=1e-7, rng=1)
    for b in points:
        r = red.solve(b)
        h_found.update(r.eigenvalues.tobytes() + r.sensitivities.tobytes())
        h_found.update(red.eigenvalues(b).tobytes())
    h_found.update(red.constant.tobytes() + red.terms.tobytes())
    print("certificate:", fast.certificate)
    print("evaluations sha256:", h_eval.hexdigest())
    print("certificate+basis sha256:", h_cert.hexdigest())
    print("foundation sha256:", h_found.hexdigest())


if __name__ == "__main__":
    main()
