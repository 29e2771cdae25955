"""Errors raised by the numerics, each with a message an operator can act on."""


class SolverError(Exception):
    """Base class: the data cannot give the answer asked for."""


class TooFewPositions(SolverError):
    """Fewer distinct positions (orientations, epochs) than the model needs."""


class NotIdentifiable(SolverError):
    """The data cannot separate some parameters (ill-conditioned or singular)."""


class SaturatedInput(SolverError):
    """An axis sits at its range limit."""


class NotFinite(SolverError, ValueError):
    """NaN or infinity reached a decomposition (overflowing or absurd input)."""
