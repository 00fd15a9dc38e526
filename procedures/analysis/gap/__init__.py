"""The model-gap workflow (DESIGN.md sections 7-8)."""
