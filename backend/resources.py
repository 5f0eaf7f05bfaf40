"""Where the console (``web/``) and the Alembic environment (``migrations/``) are.

In a source checkout, and so in an editable install, both sit at the top of the repository
beside the packages (the layout of ``ARCHITECTURE.md``).  A wheel carries them inside this
package, as ``backend/web`` and ``backend/migrations`` (``setup.py`` copies them at build
time), because a non-editable install has no repository around it.  :func:`resource_dir`
looks inside the package first, then beside it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Literal

__all__ = ["resource_dir"]

_PACKAGE = Path(__file__).resolve().parent


def resource_dir(name: Literal["web", "migrations"]) -> Path:
    """The directory ``name`` of the installed package, or of the source tree.

    Raises
    ------
    FileNotFoundError
        Neither ``backend/<name>`` (a wheel) nor ``<repository>/<name>`` exists.
    """
    if name not in ("web", "migrations"):
        raise ValueError(f"name must be 'web' or 'migrations', got {name!r}")
    candidates = (_PACKAGE / name, _PACKAGE.parent / name)
    for path in candidates:
        if path.is_dir():
            return path
    raise FileNotFoundError(
        f"VisionCell's {name}/ directory is missing (looked in "
        f"{', '.join(str(p) for p in candidates)}): reinstall the package"
    )
