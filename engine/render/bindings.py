"""Every number two pieces of GL code must agree on, in one table, and the state each pass
sets at its start.

Texture units, uniform-block binding points and clip-distance indices are fixed for the
whole engine (OpenGL 4.1 has no ``layout(binding=)``, so programs are told their units
from here when they are built; the clip-distance indices reach the GLSL as ``#define``s,
``clip_glsl_defines``, that the shader library gives every program).  A unit may serve
different samplers in different passes (a claim's parent images, a composite's reflection
images) as long as no pass binds two of them to it.

``PassState`` is everything a pass's draws depend on besides its program and inputs:
depth test and function, face culling and winding, blending, which clip distances are on,
the scissor and the viewport.  Each pass applies its whole state when it starts
(``apply_pass_state``), so no pass relies on what the one before left behind and passes
can run in any order (tests/test_pass_state.py renders them shuffled).
"""
from __future__ import annotations

from dataclasses import dataclass

import moderngl

# --- texture units -----------------------------------------------------------------------
ALBEDO_UNIT = 0          # scene: the batch's albedo map
SKY_UNIT = 1             # scene, sky, composite: the sky cube map
NODE_UNIT = 2            # scene (masked views): the level's node image
PARENT_NODE_UNIT = 3     # claim: the parent level's node image
PARENT_SURFACE_UNIT = 4  # claim: the parent level's surface image
REFLECTION_UNITS = (3, 4, 5)  # composite: the level's colour, seen-id and node images
ATLAS_UNIT = 6           # composite (rough variant): the rough-reflection atlas
LEVEL_UNITS = (3, 5)     # rough-atlas copy: a level's colour and node images (the composite's units for them)
PRESENT_UNIT = 0         # present: the HDR image
PROBE_UNIT = 7           # scene: the cube map of the batch's reflection probe
NORMAL_UNIT = 8          # scene: the batch's normal map; composite (bumpy mirrors): the mirror's
CUBE_MIP_UNIT = 14       # cube-map mip pass: the cube whose next level it draws
SCRATCH_UNIT = 15        # raw-GL copies bind their target here; no program reads it

# --- uniform-block binding points ----------------------------------------------------------
CAMERA_BINDING = 0
LIGHTS_BINDING = 1
VIEWS_BINDING = 2        # the batched scene program's table of a level's views

# --- clip distances ------------------------------------------------------------------------
# The GLSL writes gl_ClipDistance[CLIP_VIEW_PLANE] and so on: the names below, defined for
# every program (``clip_glsl_defines``), never a number.
CLIP_VIEW_PLANE = 0      # a mirror or portal view's plane (camera.clip_plane)
CLIP_RECT = (1, 2, 3, 4)  # a rectangle: views drawn in one batched draw, composite quads
CLIP_RECT_SIDES = ("LEFT", "RIGHT", "BOTTOM", "TOP")  # CLIP_RECT's order: x >= x0, x <= x1, y >= y0, y <= y1
CLIP_SLICE = 5           # an instance's slice plane (things partly through a portal)
CLIP_DISTANCE_COUNT = 6
_GL_CLIP_DISTANCE0 = 0x3000

SCENE_CLIPS = frozenset((CLIP_VIEW_PLANE, CLIP_SLICE))
BATCHED_SCENE_CLIPS = SCENE_CLIPS | frozenset(CLIP_RECT)
RECT_CLIPS = frozenset(CLIP_RECT)
NO_CLIPS: frozenset[int] = frozenset()



def clip_glsl_defines() -> dict[str, str]:
    """``CLIP_VIEW_PLANE``, ``CLIP_RECT_LEFT`` .. ``CLIP_RECT_TOP``, ``CLIP_SLICE`` and
    ``CLIP_DISTANCE_COUNT`` for the GLSL, from the indices above."""
    rect = {f"CLIP_RECT_{side}": str(index) for side, index in zip(CLIP_RECT_SIDES, CLIP_RECT, strict=True)}
    return {"CLIP_VIEW_PLANE": str(CLIP_VIEW_PLANE), **rect, "CLIP_SLICE": str(CLIP_SLICE),
            "CLIP_DISTANCE_COUNT": str(CLIP_DISTANCE_COUNT)}


# Blending "over", alpha kept: the composite's (reflection x rate + own x (1 - rate)) and the
# transparent slot's.
BLEND_OVER = (moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA, moderngl.ZERO, moderngl.ONE)


@dataclass(frozen=True)
class PassState:
    """The fixed-function state of a pass (the scissor and viewport are given per apply)."""

    depth_func: str | None = None        # None: no depth test
    cull: bool = False
    front_face: str = "ccw"
    blend: tuple[int, ...] | None = None
    clips: frozenset[int] = NO_CLIPS


def apply_pass_state(ctx: moderngl.Context, state: PassState, viewport: tuple[int, int, int, int],
                     scissor: tuple[int, int, int, int] | None = None) -> None:
    """Set every piece of ``state`` (and the viewport and scissor), whatever was set before."""
    flags = moderngl.NOTHING
    if state.depth_func is not None:
        flags |= moderngl.DEPTH_TEST
        ctx.depth_func = state.depth_func
    if state.cull:
        flags |= moderngl.CULL_FACE
    if state.blend is not None:
        flags |= moderngl.BLEND
        ctx.blend_func = state.blend
    ctx.enable_only(flags)
    ctx.front_face = state.front_face
    for index in range(CLIP_DISTANCE_COUNT):
        if index in state.clips:
            ctx.enable_direct(_GL_CLIP_DISTANCE0 + index)
        else:
            ctx.disable_direct(_GL_CLIP_DISTANCE0 + index)
    ctx.viewport = viewport
    ctx.scissor = scissor
