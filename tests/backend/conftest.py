"""Fixtures of the backend tests: settings over a copy of the migrated template database,
one user per role, and the app under a test client.

A module whose tests only read (or are refused before anything is stored) marks itself
``pytestmark = pytest.mark.shared_app``: its tests then share one database, one set of
users and one running app (the same ``settings``, ``tokens``, ``client`` and ``headers``
fixtures), built once for the module instead of once per test.  In a module where only some
tests are such, those tests carry the mark themselves and share one app among them; the
others still get their own.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest
from fastapi.testclient import TestClient

from backend.app import create_app
from backend.settings import Settings
from tests.utils.factories import make_settings, make_tokens, migrate
from tests.utils.postgres import postgres_url  # noqa: F401  (a fixture of this suite)


def _shared(request: pytest.FixtureRequest) -> bool:
    return request.node.get_closest_marker("shared_app") is not None


@pytest.fixture(scope="module")
def module_settings(tmp_path_factory) -> Settings:
    """Settings over one migrated database for a whole module."""
    s = make_settings(tmp_path_factory.mktemp("shared-app"))
    migrate(s)
    return s


@pytest.fixture(scope="module")
def module_tokens(module_settings) -> dict[str, str]:
    return make_tokens(module_settings)


@pytest.fixture(scope="module")
def module_client(module_settings, module_tokens) -> Iterator[TestClient]:
    """One running app for a module's tests (see the module doc)."""
    with TestClient(create_app(module_settings)) as c:
        yield c


@pytest.fixture
def settings(request, tmp_path):
    if _shared(request):
        return request.getfixturevalue("module_settings")
    s = make_settings(tmp_path)
    migrate(s)
    return s


@pytest.fixture
def tokens(request, settings) -> dict[str, str]:
    if _shared(request):
        return request.getfixturevalue("module_tokens")
    return make_tokens(settings)


@pytest.fixture
def client(request, settings, tokens) -> Iterator[TestClient]:
    if _shared(request):
        yield request.getfixturevalue("module_client")
        return
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
