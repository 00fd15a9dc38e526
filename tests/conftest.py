"""Fixtures every test folder may use."""

from __future__ import annotations

import pytest

import drivers.safety


@pytest.fixture
def go_safe_calls(monkeypatch):
    """The reasons ``drivers.safety.go_safe`` was called with, in order. It is wrapped, not
    replaced: each call still drives the rig safe, so a test sees both the call and its effect."""
    calls: list[str] = []
    real = drivers.safety.go_safe

    def spy(rig, why):
        calls.append(why)
        return real(rig, why)

    monkeypatch.setattr(drivers.safety, "go_safe", spy)
    return calls
