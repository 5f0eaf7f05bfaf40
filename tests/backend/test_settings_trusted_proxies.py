"""``VISIONCELL_TRUSTED_PROXIES``: empty by default, a bounded comma-separated list of IP
addresses and networks; anything else stops the start with a message naming the setting."""

from __future__ import annotations

import ipaddress

import pytest
from pydantic import ValidationError
from typer.testing import CliRunner

from backend.settings import MAX_TRUSTED_PROXIES, Settings


def test_empty_by_default(monkeypatch):
    monkeypatch.delenv("VISIONCELL_TRUSTED_PROXIES", raising=False)
    s = Settings()
    assert s.trusted_proxies == "" and s.trusted_proxy_networks() == ()


def test_a_list_from_the_environment(monkeypatch):
    monkeypatch.setenv("VISIONCELL_TRUSTED_PROXIES", " 10.0.0.5, 192.168.1.0/24 ,::1,")
    s = Settings()
    assert s.trusted_proxies == "10.0.0.5,192.168.1.0/24,::1"
    assert s.trusted_proxy_networks() == (
        ipaddress.ip_network("10.0.0.5/32"),
        ipaddress.ip_network("192.168.1.0/24"),
        ipaddress.ip_network("::1/128"),
    )


@pytest.mark.parametrize(
    "value",
    ["proxy.local", "*", "10.0.0.300", "10.0.0.0/33", "10.0.0.1 10.0.0.2", "\x00",
     ",".join(f"10.0.{i}.1" for i in range(MAX_TRUSTED_PROXIES + 1)), "1" * 5000],
)  # fmt: skip
def test_bad_values_are_refused_naming_the_setting(value):
    with pytest.raises(ValidationError, match="VISIONCELL_TRUSTED_PROXIES"):
        Settings(trusted_proxies=value)


def test_at_most_the_bound(monkeypatch):
    value = ",".join(f"10.0.{i}.1" for i in range(MAX_TRUSTED_PROXIES))
    assert len(Settings(trusted_proxies=value).trusted_proxy_networks()) == MAX_TRUSTED_PROXIES


def test_a_bad_value_stops_serve_with_the_setting_named(monkeypatch):
    from backend.cli import app

    monkeypatch.setenv("VISIONCELL_TRUSTED_PROXIES", "proxy.local")
    res = CliRunner().invoke(app, ["serve", "--no-migrate"])
    assert res.exit_code == 2
    assert "VISIONCELL_TRUSTED_PROXIES" in res.output and "proxy.local" in res.output
