"""amprep: additive-manufacturing pre-processing (CAD → closed STL/3MF within tolerance, with an error report)."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("amprep")
except PackageNotFoundError:  # running from a source tree that was never installed
    __version__ = "0.0.0"
