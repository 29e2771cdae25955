"""The station's text field: every Input of the TUI is one."""

from __future__ import annotations

from textual.widgets import Input


class Field(Input):
    """An Input that keeps its text when focused: Tab into it and type edits the value (the
    cursor at its end) instead of replacing it, Textual's default (``select_on_focus``)."""

    def __init__(self, *args, select_on_focus: bool = False, **kwargs) -> None:
        super().__init__(*args, select_on_focus=select_on_focus, **kwargs)
