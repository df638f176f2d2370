"""Error types of gripper_sim: one per concern, each with a message that says what to do."""


class GripperSimError(Exception):
    """Base class of every error gripper_sim raises on purpose."""


class ConfigError(GripperSimError):
    """A configuration file, preset name or ``--set`` override is invalid."""


class CommandError(GripperSimError):
    """A jaw, force or lift command is out of range (NaN, negative, too large)."""


class ConvergenceError(GripperSimError):
    """The implicit solver could not converge even after halving the step.

    Attributes:
        residual_history: infinity norms of the scaled Newton updates, last attempt.
        time: simulation time (s) at which the step failed.
    """

    def __init__(self, message: str, residual_history=(), time: float = float('nan')):
        super().__init__(message)
        self.residual_history = list(residual_history)
        self.time = time


class FingersClosed(ConvergenceError):
    """The deformable fingers closed on each other over the fruit: its outline is pinched
    between them (crushed there) and no step can go on.

    Attributes (besides ``ConvergenceError``'s):
        gap: m, how far apart the two fingers' outlines were.
    """

    def __init__(self, message: str, residual_history=(), time: float = float('nan'),
                 gap: float = 0.0):
        super().__init__(message, residual_history, time)
        self.gap = gap


class ConfigWarning(UserWarning):
    """A configuration key that is valid but has no effect in the set-up (or a choice
    that overrides another), issued with ``warnings.warn``; the CLI prints it as
    ``warning: ...``."""


class Terminated(KeyboardInterrupt):
    """SIGTERM (``kill``, a batch system's time limit) stopping a verb that handles it as
    Ctrl-C: the verb cleans up the same way, and the CLI exits 143 (128 + SIGTERM)."""
