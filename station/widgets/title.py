"""A one-line title bar (the app's title and the screen's subject); no clock, so
screenshots stay deterministic."""

from __future__ import annotations

from textual.widgets import Footer, Static


def footer() -> Footer:
    """Every screen's footer: compact, without the command palette's entry (ctrl+p still
    opens it; F1 says so), so each screen's keys fit in 80 columns."""
    return Footer(compact=True, show_command_palette=False)


class TitleBar(Static):
    DEFAULT_CSS = """
    TitleBar { dock: top; height: 1; background: $panel; color: $foreground; text-style: bold; padding: 0 1; }
    """

    def __init__(self, subject: str = "", **kw) -> None:
        super().__init__("", **kw)
        self.subject = subject

    def on_mount(self) -> None:
        self.update(f"{self.app.title} · {self.subject}" if self.subject else self.app.title)
