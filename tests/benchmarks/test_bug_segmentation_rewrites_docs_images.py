"""Bug: every run of the segmentation benchmark rewrote the tracked ``docs/img/segmentation*.png``.
Figures go to ``benchmarks/out/`` (git-ignored) unless ``--docs`` is given."""

from __future__ import annotations

import subprocess
from pathlib import Path
from types import SimpleNamespace

import pytest

from benchmarks import segmentation as bench
from benchmarks import segmentation_figures as figs

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture
def recorded(monkeypatch, tmp_path):
    """Run main() with the heavy parts replaced; record where each figure would go."""
    calls: list[tuple[Path, Path | None]] = []
    cases = [SimpleNamespace(name="coins", provider="skimage")]
    monkeypatch.setattr(bench, "OUT_DIR", tmp_path / "out")
    monkeypatch.setattr(bench, "DOCS_IMG", tmp_path / "docs")
    monkeypatch.setattr(bench, "all_cases", lambda providers: (cases, {}))
    monkeypatch.setattr(bench, "_warm_up", lambda: None)
    monkeypatch.setattr(bench, "run_benchmark", lambda c, r, step: [{"case": cases[0]}])
    monkeypatch.setattr(bench, "summarise", lambda rows, skipped: {})
    monkeypatch.setattr(bench, "print_table", lambda summary, console: None)
    monkeypatch.setattr(
        figs, "comparison_figure", lambda rows, out, docs=None, **kw: calls.append((out, docs))
    )
    monkeypatch.setattr(
        figs, "evolution_figure", lambda cases, out, docs=None, **kw: calls.append((out, docs))
    )
    return calls, tmp_path


def test_a_plain_run_writes_only_to_benchmarks_out(recorded):
    calls, tmp = recorded
    assert bench.main(["--providers", "skimage"]) == 0
    assert {out.name for out, _ in calls} == {"segmentation.png", "levelset_evolution.png"}
    assert all(out.parent == tmp / "out" and docs is None for out, docs in calls)


def test_docs_flag_refreshes_the_readme_copies(recorded):
    calls, tmp = recorded
    assert bench.main(["--providers", "skimage", "--docs"]) == 0
    assert all(docs == tmp / "docs" / out.name for out, docs in calls) and calls


def test_benchmarks_out_is_git_ignored():
    r = subprocess.run(
        ["git", "check-ignore", "-q", "benchmarks/out/segmentation.png"], cwd=REPO, check=False
    )
    assert r.returncode == 0
