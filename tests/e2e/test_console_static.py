"""Static checks of the console's ES modules (no browser): no HTML from strings, no CDN,
every import resolves, every page module has the page shape."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

WEB = Path(__file__).resolve().parents[2] / "web"
JS = sorted((WEB / "js").rglob("*.js"))

# Sinks that parse a string as HTML or code.
_SINKS = re.compile(
    r"\.(innerHTML|outerHTML)\b|insertAdjacentHTML|document\.write|\beval\s*\(|new\s+Function\s*\("
    r"|createContextualFragment|DOMParser"
)
_IMPORT = re.compile(
    r"""^\s*import\s[^'"]*?from\s+["']([^"']+)["']|^\s*import\s+["']([^"']+)["']""", re.M
)


def _code(path: Path) -> str:
    """The file without its comments (a comment may name what it avoids)."""
    text = path.read_text()
    text = re.sub(r"/\*.*?\*/", "", text, flags=re.S)
    return re.sub(r"(^|[^:])//.*$", r"\1", text, flags=re.M)


def test_the_console_is_split_into_modules():
    names = {p.relative_to(WEB / "js").as_posix() for p in JS}
    assert {
        "main.js",
        "api.js",
        "live.js",
        "dom.js",
        "pages/cell.js",
        "pages/calibration.js",
    } <= names
    assert not (WEB / "app.js").exists()
    html = (WEB / "index.html").read_text()
    assert '<script type="module" src="/static/js/main.js"></script>' in html
    assert len(re.findall(r"<script\b", html)) == 1


@pytest.mark.parametrize("path", JS, ids=lambda p: p.name)
def test_no_string_is_parsed_as_html_or_code(path):
    hits = [
        f"{path.name}:{n}: {line.strip()}"
        for n, line in enumerate(_code(path).splitlines(), 1)
        if _SINKS.search(line)
    ]
    assert not hits, "\n".join(hits)


def test_the_sink_check_catches_an_assignment(tmp_path):
    bad = tmp_path / "bad.js"
    bad.write_text("// innerHTML is fine in a comment\nnode.innerHTML = text;\n")
    assert [n for n, line in enumerate(_code(bad).splitlines(), 1) if _SINKS.search(line)] == [2]


@pytest.mark.parametrize("path", [*JS, WEB / "index.html", WEB / "style.css"], ids=lambda p: p.name)
def test_nothing_is_loaded_from_another_host(path):
    text = _code(path) if path.suffix == ".js" else path.read_text()
    assert not re.search(r"""(src|href|import|url)\s*[=(]?\s*["']?(https?:)?//""", text), path


@pytest.mark.parametrize("path", JS, ids=lambda p: p.name)
def test_every_import_resolves(path):
    for m in _IMPORT.finditer(path.read_text()):
        spec = m.group(1) or m.group(2)
        assert spec.startswith("./") or spec.startswith("../"), f"{path.name}: bare import {spec!r}"
        assert (path.parent / spec).resolve().is_file(), f"{path.name}: {spec!r} not found"


@pytest.mark.parametrize("path", sorted((WEB / "js" / "pages").glob("*.js")), ids=lambda p: p.name)
def test_page_modules_have_the_page_shape(path):
    code = _code(path)
    assert "export default {" in code
    for key in ("id:", "title:", "minRole:", "mount(", "unmount("):
        assert key in code, f"{path.name} lacks {key}"
    assert re.search(r"""id:\s*["']""" + re.escape(path.stem) + """["']""", code)
