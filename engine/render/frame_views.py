"""What the main stage hands the later render stages (a world resource): the frame's root
view and the targets it was drawn into.

The main stage draws the active camera's view into level 0 of the main view tree's
``LevelStack`` (the renderer owns the stack: its GPU targets live as long as the renderer)
and publishes both here, with the scene options it drew it with; the reflect stage roots its
view tree at ``main`` in ``levels``, composites into level 0 and draws the main view's
transparent slot there (``ScenePass.draw_transparent``), and the present stage presents
level 0.  A game picks through the last frame's main view (``main.view_proj``), as mirror
beam does.
"""
from __future__ import annotations

from dataclasses import dataclass

from engine.render.scene_options import TREE_ROOT, SceneOptions
from engine.render.targets import LevelStack, RenderTargets
from engine.render.views import View

__all__ = ["FrameViews"]


@dataclass
class FrameViews:
    """The root views of this frame: the main camera's (None when there is no active camera
    or nothing to draw into) and the main view tree's targets it was drawn into (``[0]``
    its image, then the reflection levels; None with no main view)."""

    main: View | None = None
    levels: LevelStack | None = None
    # What ``main`` was drawn with: the root of the reflect stage's tree, which draws its
    # transparent slot with them once the reflections are composited into level 0.
    options: SceneOptions = TREE_ROOT

    @property
    def image(self) -> RenderTargets | None:
        """Level 0: the main view, with the reflections composited in once the reflect stage
        ran (None with no main view)."""
        return self.levels[0] if self.main is not None and self.levels is not None and len(self.levels) else None
