"""What the procedures write for people: the Markdown report, figures, and the thesis's values
for the reports' reference columns (never used in a measurement)."""
