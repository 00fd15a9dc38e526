"""The modal that asks the operator (a manual rotary-table move) on behalf of the rig thread."""

from __future__ import annotations

from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Vertical
from textual.screen import ModalScreen
from textual.widgets import Input, Static

from console.keyorder import OrderedInput
from console.operator import OperatorQuestion


class OperatorScreen(ModalScreen[str]):
    BINDINGS = [Binding("escape", "abort", "abort the move")]

    DEFAULT_CSS = """
    OperatorScreen { align: center middle; }
    OperatorScreen > Vertical { width: 76; height: auto; border: thick $warning; background: $surface;
                                padding: 0 1; }
    """

    def __init__(self, question: OperatorQuestion) -> None:
        super().__init__()
        self.question = question

    def compose(self) -> ComposeResult:
        with Vertical():
            yield Static("[b]The operator is asked[/b]")
            yield Static(self.question.prompt)
            yield OrderedInput(
                placeholder="Enter when done, or the angle set, or 'abort'", id="operator-answer"
            )

    def on_input_submitted(self, event: Input.Submitted) -> None:
        self.dismiss(event.value)

    def action_abort(self) -> None:
        self.dismiss("abort")
