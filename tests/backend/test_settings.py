import pytest
from pydantic import ValidationError

from backend.settings import DEV_SECRET, Settings


def test_defaults_are_safe_and_local():
    s = Settings()
    assert s.http_host == "127.0.0.1" and s.http_port == 8000
    assert s.viser_host == "127.0.0.1" and s.viser_port == 8080
    assert s.database_url == "sqlite+aiosqlite:///var/visioncell.db"
    assert s.auth_enabled and s.secret_key.get_secret_value() == DEV_SECRET
    assert str(s.data_dir) == "../shared/data"
    assert s.driver == "sim" and s.camera == "sim"  # `make run` starts the simulated cell


def test_environment_prefix_is_read(monkeypatch):
    monkeypatch.setenv("VISIONCELL_HTTP_PORT", "9001")
    monkeypatch.setenv("VISIONCELL_DRIVER", "ideal")
    monkeypatch.setenv("VISIONCELL_DATA_DIR", "/tmp/somewhere")
    s = Settings()
    assert s.http_port == 9001 and str(s.data_dir) == "/tmp/somewhere"


def test_public_address_without_auth_is_refused():
    with pytest.raises(
        ValidationError, match=r"non-loopback address.*http_host='0\.0\.0\.0'.*auth_enabled=False"
    ):
        Settings(http_host="0.0.0.0", auth_enabled=False, secret_key="x" * 32)


def test_public_address_with_development_secret_is_refused():
    with pytest.raises(ValidationError, match="VISIONCELL_SECRET_KEY must be set"):
        Settings(viser_host="0.0.0.0")
    Settings(viser_host="0.0.0.0", secret_key="a-private-secret-of-enough-length")


def test_production_needs_a_secret():
    with pytest.raises(ValidationError, match="VISIONCELL_SECRET_KEY"):
        Settings(environment="production")


def test_short_secret_is_refused():
    with pytest.raises(ValidationError, match="at least 16 characters"):
        Settings(secret_key="short")


def test_serial_driver_needs_a_port():
    with pytest.raises(ValidationError, match="VISIONCELL_SERIAL_PORT"):
        Settings(driver="serial")


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        ("driver", "robotic", "sim"),
        ("camera", "webcam", "folder"),
        ("http_port", 0, "greater than or equal to 1"),
        ("database_url", "sqlite:///x.db", "async driver"),
        ("http_host", "my host", "IP address"),
        ("time_scale", -1, "greater than 0"),
    ],
)
def test_bad_values_name_the_setting(field, value, message):
    with pytest.raises(ValidationError) as e:
        Settings(**{field: value})
    assert field in str(e.value) and message in str(e.value)


def test_http_and_viser_ports_must_differ():
    with pytest.raises(ValidationError, match="must differ"):
        Settings(http_port=8100, viser_port=8100)
