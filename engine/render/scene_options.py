"""How a scene pass draws its views: ``SceneOptions`` and the three kinds of view that use
them (``ROOT_VIEW``, ``TREE_ROOT``, ``REFLECTION_LEVEL``).

Apart from the pass (``engine/render/scene_pass.py``) because the ones who choose them are
elsewhere: the frame's views, the view tree's walk and the probes' faces read options, not
the pass's programs and draws, and import this alone."""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class SceneOptions:
    """How ``ScenePass.draw`` draws its views (defaults: a root view such as the main camera)."""

    clear: bool = True          # clear colour, ids and depth first; False keeps a level's claim mask
    masked: bool = False        # only pixels whose node image names the view (the claimed pixels)
    sky: bool = True            # the sky behind; reflection views leave it to their composite
    batched: bool = False       # all views in one draw per batch (instanced views: batched_mirrors.py)
    reflection_filter: bool = False  # albedo filtered as reflections are (Gpu.reflection_anisotropy)
    unlit: frozenset[int] = frozenset()  # mirrors whose own shading the composites replace (shading_replaced)
    # Draw the transparent slot now; False: a view tree's root or level view, whose slot the
    # tree draws (draw_transparent) after the levels below are composited into its pixels.
    transparent: bool = True
    # Multiply the active camera's ambient occlusion (Gpu.screen_occlusion, found for this
    # view by engine/render/screen_occlusion.py) into the opaque draws' light from all round.
    occlusion: bool = False
    # Draw into the screen reflections' framebuffer with the builds that write what their
    # composite reads (engine/render/screen_reflections.py: the main view's opaque draws).
    reflections: bool = False


ROOT_VIEW = SceneOptions()
TREE_ROOT = SceneOptions(transparent=False)  # a root whose view tree draws its transparent slot
REFLECTION_LEVEL = SceneOptions(clear=False, masked=True, sky=False, reflection_filter=True, transparent=False)
