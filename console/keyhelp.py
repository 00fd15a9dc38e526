"""The help screen (``?``): every key of the panel on show, and the keys that work everywhere.

Each panel lists its keys in ``KEY_HELP`` (key, what it does), bindings and the keys its boxes take
(Tab, Enter, Space) alike; ``tests/console`` checks that every binding of a panel is listed, so
the help cannot fall behind the footer.
"""

from __future__ import annotations

from typing import ClassVar

from rich.table import Table
from textual.app import ComposeResult
from textual.binding import Binding, BindingType
from textual.containers import Vertical, VerticalScroll
from textual.screen import ModalScreen
from textual.widgets import Static

#: keys that work on every panel
GLOBAL_HELP: tuple[tuple[str, str], ...] = (
    ("F1-F6", "panels: Meters, Modes, Set-points, Record, Procedures, Spectra"),
    ("?", "this help (outside a text box); Esc closes it"),
    ("q", "quit: the rig goes safe; asks first when a recording or a procedure is live"),
    ("ctrl+q", "quit, also from a text box (where letters are typed)"),
)

PanelHelp = tuple[tuple[str, str], ...]


def help_keys(spec: str) -> set[str]:
    """The keys a help row names: "F1-F6" -> f1..f6, "0-7" -> 0..7, "Tab / shift+Tab" -> both."""
    keys: set[str] = set()
    for part in spec.replace(",", "/").split("/"):
        part = part.strip().lower()
        lo, dash, hi = part.partition("-")
        if (
            dash
            and lo[-1:].isdigit()
            and hi[-1:].isdigit()
            and lo.rstrip("0123456789") == hi.rstrip("0123456789")
        ):
            prefix = lo.rstrip("0123456789")
            keys |= {
                f"{prefix}{i}" for i in range(int(lo[len(prefix) :]), int(hi[len(prefix) :]) + 1)
            }
        elif part:
            keys.add(part)
    return keys


class HelpScreen(ModalScreen[None]):
    BINDINGS: ClassVar[list[BindingType]] = [
        Binding("escape", "close", "close"),
        Binding("question_mark", "close", "close", key_display="?"),
        Binding("q", "close", show=False),
    ]

    DEFAULT_CSS = """
    HelpScreen { align: center middle; }
    HelpScreen > Vertical { width: 90%; max-width: 100; height: auto; max-height: 90%;
                            border: thick $accent; background: $surface; padding: 0 1; }
    HelpScreen VerticalScroll { height: auto; max-height: 100%; }
    """

    def __init__(self, title: str, panel: PanelHelp) -> None:
        super().__init__()
        self.title_text = title
        self.panel = panel

    def rows(self) -> list[tuple[str, str]]:
        return [*self.panel, *GLOBAL_HELP]

    def compose(self) -> ComposeResult:
        table = Table(box=None, show_header=False, pad_edge=False, expand=True)
        table.add_column("key", style="bold", no_wrap=True)
        table.add_column("does", ratio=1)
        for key, does in self.panel:
            table.add_row(key, does)
        table.add_row("", "")
        table.add_row("", "[dim]everywhere[/dim]")
        for key, does in GLOBAL_HELP:
            table.add_row(key, does)
        with Vertical():
            yield Static(f"[b]Keys: {self.title_text}[/b]   (Esc or ? closes)")
            with VerticalScroll():
                yield Static(table, id="help-keys")

    def action_close(self) -> None:
        self.dismiss(None)
