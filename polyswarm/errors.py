"""One exception hierarchy for everything polyswarm raises on purpose.

The CLI turns any ``PolyswarmError`` into a one-line message and exit code 1;
anything else is a bug and shows a traceback.
"""


class PolyswarmError(Exception):
    """Base class of every error polyswarm raises on purpose."""


class ConfigError(PolyswarmError):
    """A configuration file or value is invalid (unknown key, wrong type, bad range)."""


class GeometryError(PolyswarmError):
    """A geometric input is unusable."""


class InvalidPolygonError(GeometryError):
    """A polygon handed to the map is not a valid, simple, counter-clockwise polygon."""


class MapError(PolyswarmError):
    """A map operation cannot be carried out."""


class DeltaGapError(MapError):
    """A delta does not apply to this map version: the receiver must fetch the full map."""


class DecodeError(PolyswarmError):
    """Bytes from the network or a file are not a valid message (never partially applied)."""


class DataFormatError(PolyswarmError):
    """An input data file (log, image, map_server YAML) is malformed."""


class PlanningError(PolyswarmError):
    """No path can be planned (start or goal outside explored free space, or unreachable)."""


class OffMapError(PlanningError):
    """The start is not in explored free space: the robot stands where its map says
    nothing is known (it must move back to known space or look around)."""


class SimulationError(PolyswarmError):
    """The simulator cannot be set up or stepped as asked."""


class CommsError(PolyswarmError):
    """A Zenoh session or message exchange failed."""
