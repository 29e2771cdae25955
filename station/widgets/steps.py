"""The step list of a guided procedure (keyboard: up/down, enter to redo a step)."""

from __future__ import annotations

from textual.widgets import OptionList
from textual.widgets.option_list import Option

MARKS = {"captured": "✓", "skipped": "–", "pending": " "}


class StepList(OptionList):
    """One line per step: a mark (✓ captured, – skipped, ▶ current, ! a captured row that
    disagrees with the others) and the name."""

    def show(self, steps, current: int, flagged=()) -> None:
        highlighted = self.highlighted
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
