"""Decide what to do with a result: save as rejected with a reason, accept as an override
with a note, or go back (and re-do). Also a yes/no confirmation for abort and quit.

Both are modal screens that return their answer through ``dismiss`` (the caller passes a
callback to ``push_screen``): ``DecideScreen`` returns ``("rejected" | "override", note)``
or None; ``ConfirmScreen`` returns True or False.
"""

from __future__ import annotations

from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Vertical
from textual.screen import ModalScreen
from textual.widgets import Input, Static

from station.widgets.field import Field
from station.widgets.notices import NoticesMixin
from station.widgets.title import footer


class DecideScreen(NoticesMixin, ModalScreen):
    """A failed result: the operator saves it as rejected, or accepts it with a note."""

    CSS = """
    DecideScreen { align: center middle; }
    DecideScreen #box { width: 76; height: auto; max-height: 22; border: round $error; background: $surface;
                        padding: 0 1; }
    DecideScreen #why { height: auto; max-height: 10; }
    DecideScreen #error { height: auto; color: $error; }
    /* the notices of the screen underneath (Results) in the box, not toasts over its field and keys */
    DecideScreen ToastHolder { display: none; }
    DecideScreen #notices { height: auto; max-height: 4; }
    DecideScreen Input:focus { border: tall $accent; }
    """
    BINDINGS = [
        Binding("ctrl+r", "decide('rejected')", "Save as rejected", priority=True),
        Binding("ctrl+o", "decide('override')", "Accept (override)", priority=True),
        Binding("escape", "cancel", "Back", priority=True),
    ]

    def __init__(self, reasons: list[str], failed: bool = True) -> None:
        super().__init__()
        self.reasons = reasons
        self.failed = failed

    def compose(self) -> ComposeResult:
        with Vertical(id="box"):
            head = (
                "[b]FAIL[/]: this result is not saved as accepted without a decision."
                if self.failed
                else "Save this result as rejected?"
            )
            lines = [head] + [f"• {r}" for r in self.reasons[:6]]
            if len(self.reasons) > 6:
                lines.append(f"… and {len(self.reasons) - 6} more")
            yield Static("\n".join(lines), id="why")
            yield Static(
                "A reason (rejected) or a note saying why it is accepted anyway:"
                if self.failed
                else "Why it is rejected (stored with the result):"
            )
            yield Field(placeholder="reason / note (required)" if self.failed else "reason (required)", id="note")
            keys = "ctrl+r save as rejected · " + ("ctrl+o accept as override · " if self.failed else "")
            yield Static(keys + "esc back (re-do: n new run)")
            yield Static("", id="error")
            yield Static("", id="notices")
        yield footer()

    def on_mount(self) -> None:
        self.query_one("#note", Input).focus()

    def check_action(self, action: str, parameters) -> bool | None:
        # only a FAIL can be accepted as an override: no ctrl+o in the footer of a passing result's box
        if action == "decide" and parameters and parameters[0] == "override" and not self.failed:
            return False
        return True

    def action_decide(self, decision: str) -> None:
        if decision == "override" and not self.failed:
            return
        note = self.query_one("#note", Input).value.strip()
        if not note:
            self.query_one("#error", Static).update("Type a reason or note first: it is stored with the result.")
            return
        self.dismiss((decision, note))

    def action_cancel(self) -> None:
        self.dismiss(None)


class ConfirmScreen(NoticesMixin, ModalScreen):
    """y / Enter confirms, n / Escape declines. The notices are lines in the box, under the
    question: as toasts (bottom right, two stacked) they lay over its last lines at 80x24."""

    CSS = """
    ConfirmScreen { align: center middle; }
    ConfirmScreen #box { width: 60; height: auto; max-height: 20; border: round $warning; background: $surface;
                         padding: 0 1; }
    ConfirmScreen ToastHolder { display: none; }
    ConfirmScreen #notices { height: auto; max-height: 6; margin-top: 1; }
    """
    BINDINGS = [
        Binding("y", "answer(True)", "Yes", priority=True),
        Binding("enter", "answer(True)", "Yes", show=False, priority=True),
        Binding("n", "answer(False)", "No", priority=True),
        Binding("escape", "answer(False)", "No", show=False, priority=True),
    ]

    def __init__(self, question: str, update=None) -> None:
        """``update``: called each half second for the question as it stands now (what a
        quit keeps changes while the run goes on behind the box)."""
        super().__init__()
        self.question = question
        self.question_now = update

    def compose(self) -> ComposeResult:
        with Vertical(id="box"):
            yield Static(self._text(), id="question")
            yield Static("", id="notices")
        yield footer()  # this box's keys: the screen underneath showed its own, dead while it is open

    def _text(self) -> str:
        return self.question + "\n\n[b]y[/] yes · [b]n[/] no"

    def on_mount(self) -> None:  # (NoticesMixin's runs too: Textual calls each class's handler)
        if self.question_now is not None:
            self.set_interval(0.5, self._refresh_question)

    def _refresh_question(self) -> None:
        question = self.question_now()
        if question != self.question:
            self.question = question
            self.query_one("#question", Static).update(self._text())

    def action_answer(self, yes: bool) -> None:
        self.dismiss(yes)


def new_run(screen, lost: str | None) -> None:
    """Leave ``screen`` for a new run (the guide dropped, the screen popped); asked first when
    ``lost`` says what the run would lose (a result not saved, a record not exported), never in a
    scripted session."""

    def go(yes: bool | None) -> None:
        if yes:
            screen.app.session.guide = None
            screen.app.pop_screen()

    if lost is None or screen.app.session.scripted:
        go(True)
    else:
        screen.app.push_screen(ConfirmScreen(f"New run? {lost}"), go)
