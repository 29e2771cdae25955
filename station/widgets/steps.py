"""The step list of a guided procedure (keyboard: up/down, enter to redo a step)."""

from __future__ import annotations

from textual.widgets import OptionList
from textual.widgets.option_list import Option

MARKS = {"captured": "✓", "skipped": "–", "pending": " "}


class StepList(OptionList):
    """One line per step: a mark (✓ captured, – skipped, ▶ current, ! a captured row that
    disagrees with the others) and the name."""

    _current: int | None = None

    def show(self, steps, current: int, flagged=()) -> None:
        """Redraw; the cursor stays where the operator put it until the run moves on to
        another step, then it follows the current one (scrolled into view: P2's 60 rows
        are taller than the list at 80x24)."""
        highlighted = self.highlighted
        if current != self._current and current >= 0:
            highlighted = None  # the run moved on: follow it
        self._current = current
        self.clear_options()
        self.add_options(
            [
                Option(
                    f"{'▶' if i == current and s.status == 'pending' else '!' if i in flagged else MARKS[s.status]}"
                    f" {i + 1:2d} {s.name}",
                    id=str(i),
                )
                for i, s in enumerate(steps)
            ]
        )
        self.highlighted = highlighted if highlighted is not None else current
