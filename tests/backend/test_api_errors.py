"""The error mapping: status from the exception's class, never its message; a bare
``ValueError`` (a bug) is a logged 500 with the JSON body."""

from __future__ import annotations

import logging

import pytest
from fastapi import FastAPI
from fastapi.testclient import TestClient

from backend.api.errors import install_error_handlers
from backend.auth import UserExists
from robot.errors import JointLimitError, TrajectoryTooLong
from vision.errors import Conflict, InvalidInput, NotFound


def _app(exc: Exception) -> TestClient:
    app = FastAPI()
    install_error_handlers(app)

    @app.get("/boom")
    async def boom() -> None:
        raise exc

    return TestClient(app, raise_server_exceptions=False)


@pytest.mark.parametrize(
    ("exc", "status", "code"),
    [
        (NotFound("no thing 3"), 404, "not_found"),
        (Conflict("already exists"), 409, "conflict"),
        (UserExists("user 'a' already exists"), 409, "conflict"),
        (InvalidInput("not found in the file"), 422, "invalid_value"),
        (JointLimitError(2, 3.0, (0.5, 2.0)), 422, "joint_limit"),
        (TrajectoryTooLong("too long", duration_s=1e9, samples=-1), 422, "trajectory_too_long"),
    ],
)
def test_domain_errors_carry_their_status(exc, status, code):
    r = _app(exc).get("/boom")
    assert r.status_code == status and r.json() == {"error": code, "detail": exc.detail}


@pytest.mark.parametrize("exc", [ValueError("already exists"), KeyError("x"), ZeroDivisionError()])
def test_a_bug_is_a_logged_500_with_the_json_body(exc, caplog):
    with caplog.at_level(logging.ERROR, logger="backend.api.errors"):
        r = _app(exc).get("/boom")
    assert r.status_code == 500
    assert r.json()["error"] == "internal_error"
    assert type(exc).__name__ in r.json()["detail"]
    assert any("internal error in GET /boom" in m for m in caplog.messages)
