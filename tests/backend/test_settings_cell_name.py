"""``Settings.cell_name`` (VISIONCELL_CELL_NAME): a short slug, default ``cell-1``."""

from __future__ import annotations

import pytest
from pydantic import ValidationError

from backend.settings import Settings


def test_default_and_environment(monkeypatch):
    assert Settings().cell_name == "cell-1"
    monkeypatch.setenv("VISIONCELL_CELL_NAME", "line-2_cell-7")
    assert Settings().cell_name == "line-2_cell-7"


@pytest.mark.parametrize(
    "bad", ["", "Cell-1", "cell 1", "-cell", "cell-", "c" * 41, "cell/1", "zelle-ü", "a;drop"]
)
def test_bad_names_are_refused_with_the_value(bad):
    with pytest.raises(ValidationError, match="cell_name must be a short slug") as info:
        Settings(cell_name=bad)
    assert repr(bad) in str(info.value)


@pytest.mark.parametrize("bad", ["", "   ", "x" * 3000])
def test_bad_camera_devices_are_refused(bad):
    with pytest.raises(ValidationError, match="camera_device must be"):
        Settings(camera_device=bad)
