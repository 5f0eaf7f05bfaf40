"""Build hook: the wheel carries the console (``web/``) and the migrations (``migrations/``).

Both live at the top of the repository, outside any Python package (the layout of
``ARCHITECTURE.md``), so ``package-data`` cannot name them.  This hook copies them into the
built ``backend`` package, as ``backend/web`` and ``backend/migrations``, where
:func:`backend.resources.resource_dir` finds them in an installed copy.  An editable install
reads them from the tree and needs no copy.  Everything else is in ``pyproject.toml``.
"""

from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

DATA_DIRS = ("web", "migrations")


class BuildPyWithData(build_py):
    """``build_py`` that also copies :data:`DATA_DIRS` into ``backend/`` of the build."""

    def run(self) -> None:
        super().run()
        if getattr(self, "editable_mode", False):
            return
        root = Path(__file__).resolve().parent
        for name in DATA_DIRS:
            for src in sorted((root / name).rglob("*")):
                if not src.is_file() or "__pycache__" in src.parts or src.suffix == ".pyc":
                    continue
                dst = Path(self.build_lib, "backend", src.relative_to(root))
                self.mkpath(str(dst.parent))
                self.copy_file(str(src), str(dst))


setup(cmdclass={"build_py": BuildPyWithData})
