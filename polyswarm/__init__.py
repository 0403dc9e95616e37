"""polyswarm: multi-robot exploration with polygon maps.

The core library (this package) holds the PolyMap format, PolySLAM, navigation and
exploration logic. It does no network or simulator I/O; the ``polyswarm`` command
(``polyswarm.cli``) is the only place that wires the simulator (``sim``), the robot
agents and coordinator (``agents``) and Zenoh together.
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("polyswarm")
except PackageNotFoundError:  # pragma: no cover - running from a source tree without install
    __version__ = "0.0.0+unknown"

__all__ = ["__version__"]
