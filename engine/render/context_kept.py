"""What outlives an engine on its GL context: kept in the context's ``extra`` (moderngl's
slot for a user's objects), so it goes when the context goes.  The programs and shadow
atlases a released engine hands to the next (``shader_library.FreePrograms``,
``free_depth_images.FreeDepthImages``) and the released samples queries
(``mirror_passes``)."""
from __future__ import annotations

from collections.abc import Callable
from typing import TypeVar

import moderngl

T = TypeVar("T")


def kept_on(ctx: moderngl.Context, key: str, make: Callable[[], T]) -> T:
    """The object kept on ``ctx`` under ``key``, made by ``make`` the first time it is asked for."""
    if not isinstance(ctx.extra, dict):
        ctx.extra = {}
    kept = ctx.extra.get(key)
    if kept is None:
        kept = ctx.extra[key] = make()
    return kept
