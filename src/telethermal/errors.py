"""The project's one error tree.

Each class also inherits the built-in exception whose meaning it carries, so
callers that only know Python's built-ins still catch the right thing.
"""


class TelethermalError(Exception):
    """Base of every error raised on purpose by telethermal."""


class UnknownMaterialError(TelethermalError, KeyError):
    """A material name that the materials table does not hold."""

    def __str__(self) -> str:  # KeyError would quote the whole message
        return str(self.args[0]) if self.args else ""


class SceneError(TelethermalError, ValueError):
    """A scene file that cannot be read, or a scene the simulator cannot model."""


class DatasetError(TelethermalError, ValueError):
    """A dataset (manifest or trial file) that breaks the dataset format."""


class ModelError(TelethermalError, ValueError):
    """Bad parameters given to a physics model."""


class IdentificationError(TelethermalError, ValueError):
    """An identifier used wrongly: unfitted, bad input, channels that do not match."""


class ModelFileError(TelethermalError, ValueError):
    """A model file that is not one, is truncated, or is from another version."""


class ControlError(TelethermalError, ValueError):
    """A controller called with an input it cannot act on (a non-positive step)."""


class ProtocolError(TelethermalError):
    """A message that does not follow the wire protocol (says which field)."""


class WindowFull(ProtocolError):
    """The lossless stream's window is full: the peer has not acknowledged
    ``WINDOW`` messages. The message was not accepted (nothing was lost: it
    was never numbered); send it again once the peer acknowledges."""


class UnknownKindError(ProtocolError):
    """A well-formed message whose ``kind`` is a string this side does not know."""


class TransportError(TelethermalError):
    """A socket, key or peer problem of the networked services."""


class CalibrationError(TelethermalError, RuntimeError):
    """A sensor calibration that could not be trusted (a drifting target, a
    fit that does not hold); the previous calibration stays in force."""


class BenchError(TelethermalError, ValueError):
    """A benchmark that cannot run as asked (names the option or the worker)."""


class OutputFolderError(TelethermalError, PermissionError):
    """A folder for results that this process cannot create or write."""


class UsageError(TelethermalError, ValueError):
    """A command-line value that cannot be used, said with its option (an
    output path that is a folder, a figure's suffix no format has)."""
