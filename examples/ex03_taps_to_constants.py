"""Hammer taps to elastic constants: synthetic taps of a known plate, imported, estimated.

A 200 x 100 x 6.6 mm orthotropic plate with known constants (E1 = 150, E2 = 10, G12 = G13
= 3, G23 = 2 GPa, nu12 = 0.25) is tapped five times at one corner and recorded at the
opposite one: the recordings (force and acceleration, 2-channel WAV files as a real
hammer test gives) come from the finite-element model on a 24 x 12 mesh, with 0.1 % noise.
``bayesplate import`` turns them into a case file with no options (the band from the
plate sheet's prior, the poles by LSCF); estimator B then reads the constants from it on
the sheet's coarser 16 x 8 mesh, starting from a data-sheet prior 10-25 % off the truth.

Run: ``python examples/ex03_taps_to_constants.py``
"""

import pathlib
import tempfile

import numpy as np

import bayesplate
from bayesplate.cli import main as bayesplate_command
from bayesplate.io.synthetic_taps import TapArtefacts, plate_modes_at, synthetic_taps, write_taps

TRUTH = np.array([150e9, 10e9, 0.25, 3e9, 3e9, 2e9])  # E1, E2, nu12, G12, G13, G23 (SI)
SHEET = """name = "orthotropic plate, 200 x 100 x 6.6 mm"
[plate]
length_mm = 200
width_mm = 100
thickness_mm = 6.6
density_kg_m3 = 1000
layup_deg = [0]
[measured]
sigma_rel = 0.01
[prior]
E1_GPa = { mean = 130, sd = 25 }
E2_GPa = { mean = 11, sd = 2 }
nu12 = { mean = 0.30, sd = 0.05 }
G12_GPa = { mean = 3.5, sd = 0.7 }
G13_GPa = { mean = 3.5, sd = 1.0 }
G23_GPa = { mean = 2.5, sd = 1.0 }
[model]
mesh = [16, 8]
"""


def main(folder=None):
    """Taps written to `folder` (default: a temporary one), imported, B estimate returned."""
    if folder is None:
        with tempfile.TemporaryDirectory() as tmp:
            return main(tmp)
    folder = pathlib.Path(folder)
    (folder / "sheet.toml").write_text(SHEET)
    plate = bayesplate.PlateModel(0.200, 0.100, 0.0066, 1000.0, [0], mesh=(24, 12))
    b = bayesplate.stiffness_from_engineering(TRUTH)
    frequency, amplitude = plate_modes_at(plate, b, (0, 0), (200, 100), n_modes=12)
    hard_tip = (0.08e-3, 0.12e-3)  # s: a short pulse excites all 12 modes (up to 7 kHz)
    taps = synthetic_taps(
        frequency, amplitude, 25600, 0.5, 5, TapArtefacts(noise=1e-3), 1, pulse_s=hard_tip
    )
    paths = write_taps(folder / "taps", taps, rate_Hz=25600)
    case_path = folder / "case.toml"
    bayesplate_command(
        ["import", *map(str, paths), "--plate", str(folder / "sheet.toml"), "-o", str(case_path)]
    )
    result = bayesplate.estimate(bayesplate.load_case(case_path), "B")
    print(f"B: {result.status}; estimate against the truth:")
    for i, name in ((0, "E1"), (1, "E2"), (3, "G12")):
        value, sd, truth = result.constants[i] / 1e9, result.sd[i] / 1e9, TRUTH[i] / 1e9
        z = (value - truth) / sd
        print(f"  {name:4s} {value:8.3f} +- {sd:6.3f} GPa (truth {truth:g}: {z:+.2f} sd)")
    return result


if __name__ == "__main__":
    main()
