"""A served cell with its PLC links on loopback, for the PLC tests: ``visioncell serve`` as a
subprocess on the ideal arm and a folder camera replaying one COIL-20 image (obj2), with two
models taught over REST from COIL-20 views, so every inspection recognises obj2 quickly."""

from __future__ import annotations

import socket
import time
from dataclasses import dataclass
from pathlib import Path

import httpx

from tests.e2e.conftest import Server, start_server
from tests.utils.factories import free_port
from tests.utils.recorded import coil_dir, coil_file, link_sequence

#: One request's bound (a hang's, on a loaded machine).
TIMEOUT_S = 60.0


def _wait_listening(port: int, server: Server, bound_s: float = 300.0) -> None:
    t0 = time.monotonic()
    while True:
        with socket.socket() as sock:
            if sock.connect_ex(("127.0.0.1", port)) == 0:
                return
        if server.proc.poll() is not None or time.monotonic() - t0 > bound_s:
            raise RuntimeError(
                f"the OPC UA server did not listen:\n{server.log.read_text()[-3000:]}"
            )
        time.sleep(0.2)


@dataclass
class PlcCell:
    server: Server
    opcua_url: str | None
    modbus_port: int | None
    tokens: dict[str, str]
    """A token per role (users ``plc-viewer``, ``plc-operator``, ``plc-engineer``)."""
    model_ids: dict[str, int]

    def headers(self, role: str) -> dict[str, str]:
        return {"Authorization": f"Bearer {self.tokens[role]}"}


def start_plc_cell(tmp_path: Path, data_dir: Path, *, opcua: bool = True, modbus: bool = True,
                   **env: str) -> PlcCell:  # fmt: skip
    """Start the cell with the links asked for (each on a free loopback port) and teach it."""
    coil = coil_dir(data_dir)
    folder = link_sequence(tmp_path / "camera", [coil_file(coil, 2, 30)])
    url = f"opc.tcp://127.0.0.1:{free_port()}/visioncell" if opcua else None
    port = free_port() if modbus else None
    extra = {
        "VISIONCELL_CAMERA_FOLDER": str(folder),
        "VISIONCELL_DATA_DIR": str(data_dir),
        "VISIONCELL_VIEW3D_ENABLED": "false",
        "VISIONCELL_THRESHOLD_FOLLOW": "false",
        # the tests of refused sign-ins must not block the others' address
        "VISIONCELL_SIGNIN_MAX_FAILURES": "100",
        **({"VISIONCELL_OPCUA_ENDPOINT": url} if url else {}),
        **({"VISIONCELL_MODBUS_PORT": str(port)} if port else {}),
        **env,
    }
    server = start_server(tmp_path, **extra)
    try:
        if url is not None:  # the OPC UA server comes up on its own thread after the cell
            _wait_listening(int(url.rsplit(":", 1)[1].split("/")[0]), server)
        tokens = {
            role: server.token(f"plc-{role}", role) for role in ("viewer", "operator", "engineer")
        }
        h = {"Authorization": f"Bearer {tokens['engineer']}"}
        ids = {}
        with httpx.Client(base_url=server.base, timeout=TIMEOUT_S) as c:
            for tok in tokens.values():  # signed in once: the E-STOP then accepts them
                r = c.get("/api/robot/state", headers={"Authorization": f"Bearer {tok}"})
                assert r.status_code == 200, r.text
            for obj in (1, 2):
                r = c.post("/api/models", json={"name": f"obj{obj}", "kind": "2d", "threshold": 0.15},
                           headers=h)  # fmt: skip
                assert r.status_code == 201, r.text
                ids[f"obj{obj}"] = r.json()["id"]
                files = [coil_file(coil, obj, k) for k in range(0, 72, 8)]
                parts = [("images", (f.name, f.read_bytes(), "image/png")) for f in files]
                r = c.post(f"/api/models/{ids[f'obj{obj}']}/views", files=parts,
                           data={"viewpoints": "1"}, headers=h)  # fmt: skip
                assert r.status_code == 201, r.text
    except BaseException:
        server.stop()
        raise
    return PlcCell(server, url, port, tokens, ids)
