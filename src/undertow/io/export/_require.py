"""Optional libraries of the exporters: a missing one is one ConfigError line saying what to
install, not an ImportError traceback."""

from __future__ import annotations

import importlib

from ...errors import ConfigError

#: import name -> pip requirement
PACKAGES = {"rasterio": "rasterio", "pyproj": "pyproj", "laspy": "laspy[lazrs]",
            "octomap": "octomap-python"}  # fmt: skip


def require(module: str, purpose: str):
    """Import ``module`` or raise one ConfigError line naming the package to install."""
    try:
        return importlib.import_module(module)
    except ImportError:
        raise ConfigError(
            f"{purpose} needs {PACKAGES.get(module, module)}: pip install 'undertow[export]'"
        ) from None
