import os
import stat

from bayesplate.io import atomic_write_text


def test_atomic_write_gives_usual_permissions_and_leaves_no_temporary(tmp_path):
    target = tmp_path / "a" / "out.md"
    atomic_write_text(target, "hello")
    assert target.read_text() == "hello"
    mask = os.umask(0)
    os.umask(mask)
    assert stat.S_IMODE(target.stat().st_mode) == 0o666 & ~mask
    assert [p.name for p in target.parent.iterdir()] == ["out.md"]


def test_case_unit_documents_keep_their_last_bits():
    """constants_json scales by 1e-9 and estimate_to_dict divides by 1e9, as they always did."""
    from types import SimpleNamespace

    import numpy as np

    from bayesplate.io import bundled_case_names, bundled_case_path, load_case
    from bayesplate.io.export import constants_json, estimate_to_dict

    rng = np.random.default_rng(0)
    scale = (1e9, 1e9, 1.0, 1e9, 1e9, 1e9)
    keys = ("E1_GPa", "E2_GPa", "nu12", "G12_GPa", "G13_GPa", "G23_GPa")
    samples = [load_case(bundled_case_path(n)).prior.mean for n in bundled_case_names()]
    samples += list(rng.uniform(0.1, 300, (200, 6)) * np.array(scale))
    for e in samples:
        sd = e * 0.0731
        doc = constants_json(e, sd)
        for i, key in enumerate(keys):
            factor = 1.0 if i == 2 else 1e-9
            assert doc[key]["mean"] == float(e[i] * factor)
            assert doc[key]["sd"] == float(sd[i] * factor)
        result = SimpleNamespace(
            settings={},
            method="B",
            converged=True,
            iterations=1,
            message="",
            n_solves=1,
            wall_time=0.0,
            constants=e,
            sd=sd,
            b=e,
            frequency_Hz=[],
            measured_Hz=[],
            residual=[],
            modes=[],
            mode_swaps=[],
            stages=(),
            status="converged",
            fit=None,
            warnings=(),
        )
        mesh = SimpleNamespace(mesh=SimpleNamespace(nx=1, ny=1))
        doc = estimate_to_dict(result, SimpleNamespace(name="x"), mesh)["constants"]
        for i, key in enumerate(keys):
            assert doc[key] == {"mean": float(e[i] / scale[i]), "sd": float(sd[i] / scale[i])}
