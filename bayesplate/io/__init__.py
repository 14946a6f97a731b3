"""The edge of the package: case files in, modal test files in, results out.

Everything that touches a file lives here; the numerics never import it.

- :mod:`~bayesplate.io.errors`: :class:`CaseError`, the one-line error of every rule.
- :mod:`~bayesplate.io.checks`: the value rules of the case format.
- :mod:`~bayesplate.io.case`: the case dataclasses (:class:`Plate`, :class:`Measurement`,
  :class:`Prior`, :class:`Case`), validated, in SI units.
- :mod:`~bayesplate.io.case_file`: reading a TOML case file (:func:`load_case`,
  :func:`parse_case`) and the bundled cases; :mod:`~bayesplate.io.case_measured`: its
  ``[measured]`` table.
- :mod:`~bayesplate.io.modal_data`, :mod:`~bayesplate.io.uff`,
  :mod:`~bayesplate.io.csv_table`: measured modes from a modal test (UFF or CSV).
- :mod:`~bayesplate.io.frf`, :mod:`~bayesplate.io.impulse`: a tap test's spectra (FRFs from
  UFF dataset 58 or CSV; impulse recordings from WAV or CSV);
  :mod:`~bayesplate.io.poles`: natural frequencies, damping and shapes by LSCF (sdypy-EMA,
  imported only then); :mod:`~bayesplate.io.poles_file`: the editable poles file and the
  stabilisation chart; :mod:`~bayesplate.io.modal_file`: any of these files by its content.
- :mod:`~bayesplate.io.case_writer`: a plate sheet plus measured modes as a case file.
- :mod:`~bayesplate.io.export`: atomic writes and the JSON documents of the results.

:mod:`~bayesplate.io.uff` (which imports ``pyuff``) is loaded only when a UFF file is read.
"""

from .case import Case, Measurement, Plate, Prior
from .case_file import bundled_case_names, bundled_case_path, load_case, parse_case
from .case_writer import (
    DEFAULT_SIGMA_REL,
    bundled_plate_names,
    bundled_plate_path,
    case_from_modal_data,
    write_case,
)
from .checks import (
    MAX_MESH_ELEMENTS,
    check_engineering_constants,
    engineering_from_si,
    engineering_to_si,
)
from .csv_table import read_frequency_csv
from .errors import CaseError
from .export import (
    atomic_write,
    atomic_write_text,
    budget_to_dict,
    constants_json,
    diagnosis_to_dict,
    estimate_to_dict,
    figure_png,
    jsonable,
    sampling_to_dict,
    save_figure,
    write_json,
    write_netcdf,
    write_png,
)
from .frf import FRFData
from .modal_data import ModalData
from .modal_file import is_tap_test, read_modal_data, read_spectra
from .poles import PoleAnalysis, extract_poles, modal_data_from_poles
from .poles_file import read_poles, write_chart, write_poles

__all__ = [
    "FRFData",
    "PoleAnalysis",
    "extract_poles",
    "is_tap_test",
    "modal_data_from_poles",
    "read_poles",
    "read_spectra",
    "write_chart",
    "write_poles",
    "MAX_MESH_ELEMENTS",
    "DEFAULT_SIGMA_REL",
    "CaseError",
    "Plate",
    "Measurement",
    "Prior",
    "Case",
    "load_case",
    "parse_case",
    "bundled_case_path",
    "bundled_case_names",
    "check_engineering_constants",
    "engineering_to_si",
    "engineering_from_si",
    "ModalData",
    "read_modal_data",
    "read_frequency_csv",
    "case_from_modal_data",
    "write_case",
    "bundled_plate_names",
    "bundled_plate_path",
    "atomic_write",
    "atomic_write_text",
    "figure_png",
    "save_figure",
    "write_netcdf",
    "jsonable",
    "write_json",
    "write_png",
    "constants_json",
    "estimate_to_dict",
    "budget_to_dict",
    "sampling_to_dict",
    "diagnosis_to_dict",
]
