"""The running VisionCell system: settings, database, REST API, 3D view, cell orchestration."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("visioncell")
except PackageNotFoundError:  # running from a source tree that was never installed
    __version__ = "0.0.0+source"

__all__ = ["__version__"]
