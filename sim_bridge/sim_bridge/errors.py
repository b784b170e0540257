"""The simulator's errors: a world that cannot be built."""


class WorldError(RuntimeError):
    """The world cannot be built (missing URDF, unknown joint or link)."""
