"""Estimator B on the paper's Plate 1: the elastic constants from 14 natural frequencies.

Plate 1 of Daghia, de Miranda, Ubertini and Viola (Composite Structures 80, 2007, 461-473)
is a 200 x 100 x 6.6 mm single orthotropic layer whose 14 lowest free-free frequencies the
authors computed at E1 = 150, E2 = 10, G12 = G13 = 3, G23 = 2 GPa, nu12 = 0.25. The bundled
case starts from their Test 1 (E1 = 100 GPa, ...) with deviations of 1/6 of each value and
pairs the peaks with the computed modes by order, as the paper does. B, the Bayesian
estimate (the posterior's mode, eq. 9), stays between the prior and the truth: Table 3
prints E1 = 145.0 GPa after 15 iterations.

Run: ``python examples/ex02_paper_plate1.py``
"""

import bayesplate

NAMES = ("E1_GPa", "E2_GPa", "nu12", "G12_GPa", "G13_GPa", "G23_GPa")
SCALE = (1e9, 1e9, 1.0, 1e9, 1e9, 1e9)  # SI to the units of NAMES


def main():
    """B on plate1: the result, its constants printed with their deviations."""
    case = bayesplate.load_case(bayesplate.bundled_case_path("plate1"))
    result = bayesplate.estimate(case, "B", pairing="order")
    print(f"B: {result.status} after {result.iterations} iterations")
    for name, scale, value, sd, truth in zip(
        NAMES, SCALE, result.constants, result.sd, case.reference, strict=True
    ):
        print(f"{name:8s} {value / scale:9.4f} +- {sd / scale:7.4f}   (truth {truth / scale:g})")
    return result


if __name__ == "__main__":
    main()
