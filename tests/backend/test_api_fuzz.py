"""Property test of the whole API: requests generated from the app's OpenAPI schema by
schemathesis (valid ones, then invalid ones) for every operation, sent with an engineer's
token to a real uvicorn server running the ideal arm and an image-folder camera.

Every answer must be below 500, and every error must be the JSON body
``{"error": code, "detail": text}``.  The examples per operation are bounded
(:data:`POSITIVE_EXAMPLES`, :data:`NEGATIVE_EXAMPLES`) and the generation is derandomised,
so a run is repeatable and takes a minute or two.
"""

from __future__ import annotations

import json
import tempfile
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest
import schemathesis
from hypothesis import HealthCheck, Phase, given
from hypothesis import settings as hyp_settings
from hypothesis import strategies as st
from hypothesis.errors import Unsatisfiable
from pydantic import ValidationError
from schemathesis import GenerationMode
from typer.testing import CliRunner

from backend.app import create_app
from backend.cli import app as cli_app
from backend.settings import MAX_TRUSTED_PROXIES, Settings
from tests.utils.factories import make_settings, make_tokens, migrate
from tests.utils.servers import RunningServer, run_uvicorn

#: Generated requests per operation: schema-valid ones (reach the handlers) ...
POSITIVE_EXAMPLES = 10
#: ... and schema-invalid ones (must be refused with a JSON 4xx).
NEGATIVE_EXAMPLES = 4


def _operations() -> list[tuple[str, str]]:
    with tempfile.TemporaryDirectory() as tmp:
        spec = create_app(make_settings(Path(tmp))).openapi()
    return [
        (method.upper(), path)
        for path, item in sorted(spec["paths"].items())
        for method in sorted(item)
        if method in ("get", "post", "put", "delete", "patch")
    ]


OPERATIONS = _operations()


@pytest.fixture(scope="module")
def fuzz_server(tmp_path_factory) -> Iterator[tuple[RunningServer, dict[str, str]]]:
    tmp = tmp_path_factory.mktemp("fuzz")
    # The 3D view runs too, so that its link route is fuzzed against a real view.
    # The peer (127.0.0.1) is a trusted proxy: every request passes the proxy-header layer.
    settings = make_settings(
        tmp, time_scale=100.0, camera_fps=2.0, camera_idle_fps=0.5, view3d_enabled=True,
        trusted_proxies="127.0.0.1",
    )  # fmt: skip
    migrate(settings)
    token = make_tokens(settings)["engineer"]
    with run_uvicorn(create_app(settings)) as srv:
        yield srv, {"Authorization": f"Bearer {token}"}


@pytest.fixture(scope="module")
def api_schema(fuzz_server):
    srv, _ = fuzz_server
    return schemathesis.openapi.from_dict(srv.app.openapi())


def _check(case, response) -> None:
    where = (
        f"{case.method} {case.formatted_path} query={case.query!r} body={case.body!r:.300}"
        f" -> {response.status_code}: {response.content[:300]!r}"
    )
    assert response.status_code < 500, where
    if response.status_code >= 400:
        assert response.headers.get("content-type", [""])[0].startswith("application/json"), where
        body = json.loads(response.content)
        # A failed solve with ?wait=true adds the job to the error body.
        assert set(body) - {"job"} == {"error", "detail"}, where
        assert isinstance(body["error"], str) and isinstance(body["detail"], str), where


def test_every_operation_is_fuzzed():
    assert len(OPERATIONS) >= 45
    assert ("POST", "/api/robot/move") in OPERATIONS
    for op in (("POST", "/api/recognition/recognise"), ("GET", "/api/recognition/threshold"),
               ("GET", "/api/recognition/negatives"), ("POST", "/api/recognition/negatives"),
               ("DELETE", "/api/recognition/negatives/{negative_id}"),
               ("GET", "/api/calibration/calibrations/{calibration_id}/export"),
               ("POST", "/api/calibration/calibrations/import")):  # fmt: skip
        assert op in OPERATIONS, op


@pytest.mark.parametrize(("method", "path"), OPERATIONS, ids=[f"{m} {p}" for m, p in OPERATIONS])
def test_no_5xx_and_every_error_is_json(fuzz_server, api_schema, method, path):
    srv, auth = fuzz_server
    operation = api_schema[path][method]
    for mode, n in (
        (GenerationMode.POSITIVE, POSITIVE_EXAMPLES),
        (GenerationMode.NEGATIVE, NEGATIVE_EXAMPLES),
    ):

        @given(case=operation.as_strategy(generation_mode=mode))
        @hyp_settings(
            max_examples=n,
            deadline=None,
            derandomize=True,
            database=None,
            phases=[Phase.generate],
            suppress_health_check=list(HealthCheck),
        )
        def run(case) -> None:
            _check(case, case.call(base_url=srv.base, headers=auth, timeout=60))

        try:
            run()
        except Unsatisfiable:
            # No parameters and no body: there is no invalid request to build.
            assert mode is GenerationMode.NEGATIVE, f"{method} {path}: no valid request built"


_FUZZ = hyp_settings(
    max_examples=40, deadline=None, derandomize=True, database=None,
    phases=[Phase.generate], suppress_health_check=list(HealthCheck),
)  # fmt: skip
_HEADER_TEXT = st.text(st.characters(min_codepoint=0x20, max_codepoint=0x7E), max_size=300).map(
    str.strip
) | st.lists(st.ip_addresses().map(str) | st.just("garbage"), max_size=40).map(", ".join)


def test_forwarded_for_headers_from_a_trusted_proxy(fuzz_server):
    """Any ``X-Forwarded-For`` from the trusted proxy: answered below 500, the E-STOP too."""
    srv, auth = fuzz_server

    @given(header=_HEADER_TEXT)
    @_FUZZ
    def run(header: str) -> None:
        with httpx.Client(base_url=srv.base, timeout=60) as c:
            for method, path, hdr in (("GET", "/api/health", {}), ("GET", "/api/robot/state", auth),
                                      ("POST", "/api/robot/estop", auth)):  # fmt: skip
                r = c.request(method, path, headers={**hdr, "X-Forwarded-For": header})
                assert r.status_code < 500, (path, header, r.text[:200])

    run()


@given(value=st.text(max_size=200) | _HEADER_TEXT.map(lambda t: t.replace(" ", "")))
@_FUZZ
def test_trusted_proxies_setting(value: str) -> None:
    """``VISIONCELL_TRUSTED_PROXIES``: any text is accepted as networks or refused naming
    the setting, never another error."""
    try:
        networks = Settings(trusted_proxies=value).trusted_proxy_networks()
    except ValidationError as exc:
        assert "VISIONCELL_TRUSTED_PROXIES" in str(exc)
    else:
        assert len(networks) <= MAX_TRUSTED_PROXIES


def test_estop_cli_options(fuzz_server):
    """``visioncell estop --timeout --url``: any value exits 0, 1 (refused, unreachable) or
    2 (a bad option), never with a traceback."""
    srv, auth = fuzz_server
    token = auth["Authorization"].split()[1]
    runner = CliRunner()

    @given(
        timeout=st.floats(allow_nan=True, allow_infinity=True) | st.floats(0.5, 30.0),
        suffix=st.text(st.characters(min_codepoint=0x21, max_codepoint=0x7E), max_size=40),
    )
    @_FUZZ
    def run(timeout: float, suffix: str) -> None:
        args = [
            "estop",
            "--token",
            token,
            "--url",
            srv.base + "/" + suffix,
            "--timeout",
            repr(timeout),
        ]
        res = runner.invoke(cli_app, args)
        assert res.exit_code in (0, 1, 2), (args, res.output)
        assert res.exception is None or isinstance(res.exception, SystemExit), (args, res.output)

    run()
