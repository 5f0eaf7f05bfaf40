"""The load switch ``VISIONCELL_FAST_READS`` is a boolean, on by default; anything that is
not a boolean is refused naming the setting."""

from __future__ import annotations

import pytest
from pydantic import ValidationError

from backend.settings import Settings


def test_the_switch_defaults_on_and_can_be_turned_off(monkeypatch) -> None:
    assert Settings().fast_reads is True
    monkeypatch.setenv("VISIONCELL_FAST_READS", "false")
    assert Settings().fast_reads is False


@pytest.mark.parametrize("value", ["maybe", "2", "-1", "nan", ""])
def test_a_value_that_is_not_a_boolean_is_refused(monkeypatch, value) -> None:
    monkeypatch.setenv("VISIONCELL_FAST_READS", value)
    with pytest.raises(ValidationError, match="fast_reads"):
        Settings()
