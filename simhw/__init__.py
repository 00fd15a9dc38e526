"""fbs-hil package."""
