"""Bug: the API answered before its unit of work was committed.

The request's database session is a FastAPI dependency with ``yield``; by FastAPI's default
its exit (the commit) ran after the response had been sent.  A client creating a calibration
session and uploading samples to it at once got 404 on the upload when the commit had not
landed yet (the e2e calibration test failed so in CI under load), and a commit that failed
after the response was lost while the client had been told 201.  The commit now ends before
the response starts.
"""

from __future__ import annotations

from sqlalchemy.ext.asyncio import AsyncSession
from starlette.testclient import TestClient

from backend.app import create_app


def test_the_commit_ends_before_the_response_starts(settings, headers, monkeypatch):
    app = create_app(settings)
    events: list[str] = []

    async def recording_app(scope, receive, send):
        async def send_(message):
            if message["type"] == "http.response.start":
                events.append("response")
            await send(message)

        await app(scope, receive, send_)

    real_commit = AsyncSession.commit

    async def commit(self):
        await real_commit(self)
        events.append("commit")

    with TestClient(recording_app) as c:
        monkeypatch.setattr(AsyncSession, "commit", commit)
        events.clear()
        r = c.post(
            "/api/calibration/sessions",
            headers=headers["engineer"],
            json={"kind": "intrinsic", "board": {"cols": 9, "rows": 6, "square_mm": 30}},
        )
        assert r.status_code == 201, r.text
        assert "commit" in events and "response" in events, events
        assert events[-1] == "response", events
