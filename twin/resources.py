"""Where the MJCF models, scenes and shipped configs are, installed or in a checkout.

A wheel carries ``models/`` and ``scenes/`` as ``twin/_data/``; a source checkout (editable
install, or running from the tree) has them at the repository's top. Both are found here, so
no other module guesses paths.
"""

from __future__ import annotations

from pathlib import Path

from twin.core.errors import TwinError

_PACKAGE_DIR = Path(__file__).resolve().parent


def data_dir(name: str) -> Path:
    """Return the directory ``models`` or ``scenes`` (installed copy first, then the checkout)."""
    for candidate in (_PACKAGE_DIR / "_data" / name, _PACKAGE_DIR.parent / name):
        if candidate.is_dir():
            return candidate
    raise TwinError(
        f"the {name}/ directory was found neither in the installed package nor beside it; "
        "reinstall the package (pip install .)"
    )


def models_dir() -> Path:
    return data_dir("models")


def scenes_dir() -> Path:
    return data_dir("scenes")
