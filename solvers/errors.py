"""Errors raised by the numerics, each with a message an operator can act on."""


class SolverError(Exception):
    """Base class: the data cannot give the answer asked for. ``alternative``: a method of the
    same procedure these data do allow (the message says which and why), else None."""

    def __init__(self, *args, alternative: str | None = None) -> None:
        super().__init__(*args)
        self.alternative = alternative


class TooFewPositions(SolverError):
    """Fewer distinct positions (orientations, epochs) than the model needs."""


class NotIdentifiable(SolverError):
    """The data cannot separate some parameters (ill-conditioned or singular)."""


class SaturatedInput(SolverError):
    """An axis sits at its range limit."""


class NotFinite(SolverError, ValueError):
    """NaN or infinity reached a decomposition (overflowing or absurd input)."""
