"""The load switches (issue 16): ``VISIONCELL_FAST_READS`` and ``VISIONCELL_REFRESH_AHEAD``
are booleans, on by default; anything that is not a boolean is refused naming the
setting, and the caches refuse a non-boolean switch in the core too."""

from __future__ import annotations

import pytest
from pydantic import ValidationError

from backend.authcache import AuthCache
from backend.readcache import ReadCache
from backend.settings import Settings


def test_both_switches_default_on_and_can_be_turned_off(monkeypatch) -> None:
    s = Settings()
    assert s.fast_reads is True and s.refresh_ahead is True
    monkeypatch.setenv("VISIONCELL_FAST_READS", "false")
    monkeypatch.setenv("VISIONCELL_REFRESH_AHEAD", "false")
    s = Settings()
    assert s.fast_reads is False and s.refresh_ahead is False


@pytest.mark.parametrize("name", ["VISIONCELL_FAST_READS", "VISIONCELL_REFRESH_AHEAD"])
@pytest.mark.parametrize("value", ["maybe", "2", "-1", "nan", ""])
def test_a_value_that_is_not_a_boolean_is_refused(monkeypatch, name, value) -> None:
    monkeypatch.setenv(name, value)
    field = name.removeprefix("VISIONCELL_").lower()
    with pytest.raises(ValidationError, match=field):
        Settings()


@pytest.mark.parametrize("cache", [ReadCache, AuthCache])
@pytest.mark.parametrize("value", [1, "yes", None])
def test_the_caches_refuse_a_switch_that_is_not_a_bool(cache, value) -> None:
    with pytest.raises(TypeError, match="refresh_ahead"):
        cache(refresh_ahead=value)
