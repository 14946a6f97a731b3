"""Loading a study of ``studies/`` (a folder of scripts, not a package) in a test."""

import importlib.util
from pathlib import Path

STUDIES = Path(__file__).resolve().parents[1] / "studies"


def load_study(path, name=None):
    """The study script at ``path`` (or ``studies/<path>.py``), executed as a module."""
    path = Path(path) if Path(path).suffix == ".py" else STUDIES / f"{path}.py"
    spec = importlib.util.spec_from_file_location(name or path.stem, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module
