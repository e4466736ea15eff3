"""The project's one exception tree; adapters translate vendor errors into it with ``from exc``."""


class StandoffError(Exception):
    """Base of every error this project raises on purpose."""


class ConfigError(StandoffError):
    """A configuration file or command-line value is malformed or out of range."""


class InputError(StandoffError):
    """A data file or message (measurements, truth, a bus payload) is malformed."""


class LinkError(StandoffError):
    """A vehicle link failed: no connection, a refused command, a vehicle that stops answering."""


class BusError(StandoffError):
    """The message bus failed: broker unreachable, publish refused."""
