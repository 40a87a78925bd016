"""What a report records so that it can be redone: tswm's version, the machine and the package versions."""
from __future__ import annotations

import os
import platform
from importlib import metadata


def _tswm_version() -> str:
    try:
        return metadata.version("tswm")
    except metadata.PackageNotFoundError:  # run from a source tree that was never installed
        return "0.1.0+source"


TSWM_VERSION = _tswm_version()

def package_versions(names) -> dict:
    """Python's version and each named distribution's ("not installed" if absent)."""
    versions = {"python": platform.python_version()}
    for name in names:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = "not installed"
    return versions


def cpu_model() -> str:
    """The CPU's model name (/proc/cpuinfo on Linux), else what platform knows."""
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def machine() -> dict:
    return {"platform": platform.platform(), "machine": platform.machine(), "cpu": cpu_model(),
            "cores": os.cpu_count()}
