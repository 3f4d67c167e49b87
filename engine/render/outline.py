"""The editor's selection outline: one full-screen pass over the main view's seen-id image,
drawn over the finished frame (after present, before the overlay). Because the seen-id
image follows reflections (a mirror's pixels hold what the mirror shows), the one pass
outlines the selected entity in every view it appears in: directly, in mirrors, through
portals. ``shaders/selection_outline.frag`` says which pixels it colours."""
from __future__ import annotations

import moderngl

from engine.core.world import World
from engine.render.bindings import OUTLINE_UNIT, PassState, apply_pass_state, bind_texture
from engine.render.shader_library import ShaderLibrary
from engine.render.targets import RenderTargets

OUTLINE_COLOR = (1.0, 0.55, 0.0, 1.0)  # orange: seen on the sky, on floors and in tinted mirrors
OUTLINE_RADIUS = 1                     # pixels round the selection's shapes (RADIUS in the shader)
_OUTLINE = PassState()                 # no depth, no blend: the outline's colour replaces the frame's


def outline_ids(targets: RenderTargets, world: World, entity: int) -> moderngl.Texture:
    """The id image to outline ``entity`` in: the seen-id image (the entity wherever it shows,
    reflections included), or for a mirror or portal the surface-id image, since the pixels
    of its seen-id image hold what it shows, not itself."""
    surface = any(type(c).__name__ in ("Mirror", "Portal") for c in world.components_of(entity))
    return targets.surface if surface else targets.seen


class SelectionOutline:
    """Draws the outline of one entity from a seen-id texture into a framebuffer."""

    def __init__(self, ctx: moderngl.Context, shaders: ShaderLibrary, radius: int = OUTLINE_RADIUS) -> None:
        if not isinstance(radius, int) or not 1 <= radius <= 8:
            raise ValueError(f"the selection outline's radius is 1 to 8 pixels, got {radius!r}")
        self.ctx = ctx
        program = shaders.program("present.vert", "selection_outline.frag", defines={"RADIUS": str(radius)})
        program["seen_ids"].value = OUTLINE_UNIT
        self._vao = ctx.vertex_array(program, [])

    def draw(self, seen_ids: moderngl.Texture, output: moderngl.Framebuffer, size: tuple[int, int],
             selected: int, color: tuple[float, float, float, float] = OUTLINE_COLOR) -> None:
        """Outline ``selected`` (an entity id; 0 or less draws nothing) over ``output``."""
        if selected <= 0:
            return
        output.use()
        apply_pass_state(self.ctx, _OUTLINE, (0, 0, *size))
        bind_texture(self.ctx, seen_ids, OUTLINE_UNIT)
        program = self._vao.program
        program["selected"].value = int(selected)
        program["outline_color"].value = tuple(float(c) for c in color)
        self._vao.render(moderngl.TRIANGLES, vertices=3)

    def release(self) -> None:
        self._vao.release()
