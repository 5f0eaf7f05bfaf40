"""Bug: ``GET /api/status`` parsed every Alembic revision script on each call (~50 ms on
the event loop, stalling every other request under load).  The head revision is read once
per process now."""

from __future__ import annotations

from alembic.script import ScriptDirectory

from backend.db.migrate import head_revision


def test_status_does_not_read_the_revision_scripts_again(client, headers, monkeypatch):
    first = client.get("/api/status", headers=headers["viewer"])
    assert first.status_code == 200
    head = first.json()["database"]["head"]
    assert head == head_revision() is not None

    def refuse(*_a, **_k):
        raise AssertionError("the revision scripts were read again")

    monkeypatch.setattr(ScriptDirectory, "from_config", refuse)
    for _ in range(3):
        r = client.get("/api/status", headers=headers["viewer"])
        assert r.status_code == 200, r.text
        assert r.json()["database"]["head"] == head
