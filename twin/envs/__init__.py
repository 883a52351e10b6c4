"""Gymnasium environments of the twin, registered on import (``import twin.envs``).

* ``twin/ObjectSearch-v0`` (``twin.envs.object_search.ObjectSearchEnv``): find the objects of a
  config by choosing, view after view, which candidate view the robot takes next; an episode is
  one search mission in a reset world (see that module).

``gymnasium`` is an optional extra: ``pip install 'bearing-twin[gym]'`` (or ``'.[gym]'`` in a
checkout).
"""

from __future__ import annotations

from twin.core.errors import TwinError


class MissingExtraError(TwinError, ImportError):
    """An optional dependency is not installed: a ``TwinError`` (one line for the user) and an
    ``ImportError`` (so ``pytest.importorskip`` and ``try: import`` treat it as one)."""


try:
    import gymnasium
except ImportError:
    raise MissingExtraError(
        "twin.envs needs gymnasium, which is not installed; pip install 'bearing-twin[gym]'"
    ) from None

OBJECT_SEARCH = "twin/ObjectSearch-v0"

if OBJECT_SEARCH not in gymnasium.registry:  # a module reloaded must not register it twice
    gymnasium.register(
        id=OBJECT_SEARCH,
        entry_point="twin.envs.object_search:ObjectSearchEnv",
        # The env ends its own episodes (view and time budget): no TimeLimit wrapper on top.
        max_episode_steps=None,
    )

__all__ = ["OBJECT_SEARCH", "MissingExtraError"]
