"""An ``Input`` that applies its keys in the order they were typed.

Textual's ``Input`` inserts a printable key in its own key handler, but runs its editing keys
(Backspace, Delete, the cursor keys, Enter) as bindings, which the app dispatches only after
the key event has bubbled back up through the widget tree: one message queue per hop. A burst
of keys from a real terminal (a fast typist, a paste, ``tmux send-keys``) therefore reaches
the box reordered: "12", Backspace, Backspace, "3" leaves "1", not "3" - and Enter would send
1 V where the operator typed 3 V. (Textual 8.2; Pilot presses keys one at a time, awaiting
each, so its tests never see it.) ``OrderedInput`` runs its own bindings in its key handler,
where the printable keys are handled, so every key takes effect in arrival order.
"""

from __future__ import annotations

from textual import events
from textual.widgets import Input


class OrderedInput(Input):
    async def _on_key(self, event: events.Key) -> None:
        bindings = self._bindings.key_to_bindings.get(event.key)
        if bindings:
            # the box's own editing key: here, in turn, not after a round trip via the app
            event.stop()
            event.prevent_default()
            self._restart_blink()
            await self.run_action(bindings[0].action)
            return
        await super()._on_key(event)
