from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest
from fastapi.testclient import TestClient

from backend.app import create_app
from tests.utils.factories import make_settings, make_tokens, migrate
from tests.utils.postgres import postgres_url  # noqa: F401  (a fixture of this suite)


@pytest.fixture
def settings(tmp_path):
    s = make_settings(tmp_path)
    migrate(s)
    return s


@pytest.fixture
def tokens(settings) -> dict[str, str]:
    return make_tokens(settings)


@pytest.fixture
def client(settings, tokens) -> Iterator[TestClient]:
    app = create_app(settings)
    with TestClient(app) as c:
        yield c


@pytest.fixture
def headers(tokens) -> dict[str, Any]:
    """``headers["viewer"]`` etc.: Authorization headers per role."""
    return {role: {"Authorization": f"Bearer {tok}"} for role, tok in tokens.items()}


@pytest.fixture(scope="session")
def synthetic_folder(tmp_path_factory):
    """Rendered calibration images (8 views + 1 blank) and their robot poses, written once."""
    from tests.utils.calibration import write_synthetic_folder

    return write_synthetic_folder(tmp_path_factory.mktemp("calib") / "views")
