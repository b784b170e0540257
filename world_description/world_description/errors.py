"""The errors of the world package: a world file, or a resource it names, that cannot be used.
Every module of the package raises these; none imports another for its errors."""


class WorldConfigError(ValueError):
    """A world file that cannot be used; the message names the file and the field."""


class ResourceError(WorldConfigError):
    """A ``package://`` resource whose package is not found."""
