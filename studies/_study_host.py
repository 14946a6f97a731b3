"""The machine a study ran on, for its report (a helper of this folder, not a study)."""

import pathlib
import platform


def cpu():
    """The processor's model name (from /proc/cpuinfo), else the machine type."""
    try:
        for line in pathlib.Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.machine()
