"""``python -m backend.cli``: the same as the ``visioncell`` console script."""

from backend.cli import main

main()
