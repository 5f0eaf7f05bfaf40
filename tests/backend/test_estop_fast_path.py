"""The REST E-STOP of a known token is answered in front of FastAPI (``EStopFastPath``)
with the route's own answer; everything else goes to the route unchanged."""

from __future__ import annotations

from backend.api import deps
from backend.api.deps import runtime_of
from backend.api.errors import ApiError
from robot.errors import LinkDown


def test_the_fast_answer_is_the_routes(client, headers):
    rt = runtime_of(client.app)

    async def route_taken() -> None:
        raise ApiError(418, "route_taken", "the request went through the FastAPI route")

    client.app.dependency_overrides[deps.estop_user] = route_taken
    fast = client.post("/api/robot/estop", headers=headers["viewer"])
    assert fast.status_code == 200, fast.text  # answered in front of the route
    # a query string goes to the route
    assert client.post("/api/robot/estop?x=1", headers=headers["viewer"]).status_code == 418
    client.app.dependency_overrides.clear()
    assert client.post("/api/robot/reset", headers=headers["operator"]).status_code == 200
    routed = client.post("/api/robot/estop?x=1", headers=headers["viewer"])
    assert routed.status_code == 200
    assert fast.headers["content-type"] == routed.headers["content-type"] == "application/json"
    a, b = fast.json()["state"], routed.json()["state"]
    assert set(a) == set(b) and a["estopped"] is b["estopped"] is True
    assert rt.cell.estopped


def test_an_arm_that_cannot_stop_is_a_json_error(client, headers):
    rt = runtime_of(client.app)

    async def unreachable() -> None:
        raise LinkDown("the serial link is down")

    rt.cell.driver.estop = unreachable
    r = client.post("/api/robot/estop", headers=headers["viewer"])
    assert r.status_code == 503 and r.json() == {
        "error": "link_down",
        "detail": "the serial link is down",
    }


def test_refusals_come_from_the_route(client):
    r = client.post("/api/robot/estop")
    assert r.status_code == 401 and r.headers["WWW-Authenticate"] == "Bearer"
    r = client.post("/api/robot/estop", headers={"Authorization": "Basic abc"})
    assert r.status_code == 401
