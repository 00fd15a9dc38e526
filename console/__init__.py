"""The operator console (``fbs console``): a Textual terminal successor of the thesis's control
console (II C.2). See docs/console.md. Textual is imported only by ``console.app`` and the
widget modules; the rig worker and its stores are plain Python."""
