"""The one place an OpenGL context is made and checked.

Speculum's baseline is OpenGL 4.1 core (macOS's ceiling): every shader is
``#version 410 core`` and nothing needs SSBOs, compute or ``layout(binding=)``.  The check
runs once at start-up and names every missing version or limit at once, so a user on an
old driver reads one clear message instead of a shader compile error later.
"""
from __future__ import annotations

import os
from dataclasses import dataclass

import moderngl

from engine.core.errors import GLCapabilityError

REQUIRED_VERSION = 410
SOFTWARE_RENDERERS = ("llvmpipe", "softpipe", "swrast", "swiftshader", "software rasterizer")


def software_renderer(renderer: str) -> bool:
    """Whether the GL_RENDERER string ``renderer`` names a software rasteriser."""
    name = renderer.lower()
    return any(word in name for word in SOFTWARE_RENDERERS)


@dataclass(frozen=True)
class GLCapabilities:
    """What the context offers, read once from GL."""

    version_code: int
    renderer: str
    max_texture_size: int
    max_cube_map_size: int
    max_color_attachments: int
    max_draw_buffers: int
    max_uniform_block_size: int
    max_vertex_attribs: int
    max_geometry_output_vertices: int
    max_clip_distances: int
    extensions: frozenset[str]
    max_texture_image_units: int = 16   # a fragment stage's samplers (GL 4.1's least: 16)

    @property
    def software(self) -> bool:
        """A software rasteriser (llvmpipe, softpipe, SwiftShader): shading is CPU time."""
        return software_renderer(self.renderer)

    @property
    def filters_anisotropically(self) -> bool:
        """Whether reflections, normal and height maps and the lights' images filter
        anisotropically (``Gpu.reflection_anisotropy``, ``normal_map_anisotropy``): on a GPU
        yes; on a software rasteriser no.  There the filter costs about 60% of a reflection
        view, and llvmpipe's (Mesa 22.3) is not the GL's: it stretches its taps along the
        screen's derivatives where the shader gives the level or the gradients itself (a
        textureLod at 8x differs from 1x at every pixel, where GLSL makes its derivatives 0),
        and these reads do.  Read from the renderer's name alone, not ``software``: the tests'
        ``SPECULUM_AS_GPU`` runs take a GPU's other branches on llvmpipe, with its filtering."""
        return not software_renderer(self.renderer)

    @classmethod
    def read(cls, ctx: moderngl.Context) -> GLCapabilities:
        info = ctx.info
        return cls(
            version_code=ctx.version_code,
            renderer=str(info.get("GL_RENDERER", "?")),
            max_texture_size=int(info.get("GL_MAX_TEXTURE_SIZE", 0)),
            max_cube_map_size=int(info.get("GL_MAX_CUBE_MAP_TEXTURE_SIZE", 0)),
            max_color_attachments=int(info.get("GL_MAX_COLOR_ATTACHMENTS", 0)),
            max_draw_buffers=int(info.get("GL_MAX_DRAW_BUFFERS", 0)),
            max_uniform_block_size=int(info.get("GL_MAX_UNIFORM_BLOCK_SIZE", 0)),
            max_vertex_attribs=int(info.get("GL_MAX_VERTEX_ATTRIBS", 0)),
            max_geometry_output_vertices=int(info.get("GL_MAX_GEOMETRY_OUTPUT_VERTICES", 0)),
            max_clip_distances=int(info.get("GL_MAX_CLIP_DISTANCES", 0)),
            extensions=frozenset(ctx.extensions),
            max_texture_image_units=int(info.get("GL_MAX_TEXTURE_IMAGE_UNITS", 0)),
        )


# (field, minimum, what the engine uses it for)
REQUIREMENTS: tuple[tuple[str, int, str], ...] = (
    ("version_code", REQUIRED_VERSION, "OpenGL 4.1 core: #version 410 shaders, textureQueryLod, geometry shaders"),
    ("max_texture_size", 2048, "render targets and textures"),
    ("max_cube_map_size", 512, "sky and probe cube maps"),
    ("max_color_attachments", 2, "colour + entity-id render targets"),
    ("max_draw_buffers", 2, "colour + entity-id render targets"),
    ("max_uniform_block_size", 16384, "camera, light and mirror uniform blocks"),
    ("max_vertex_attribs", 16, "per-instance model matrix and material record"),
    ("max_geometry_output_vertices", 256, "batched mirror and layered cube-map passes"),
    ("max_clip_distances", 6, "clip planes: view plane, batched mirror rectangles, portal slices"),
    ("max_texture_image_units", 16, "the scene shader's samplers (spot light cookies take a 17th where there is one)"),
)


def check_capabilities(caps: GLCapabilities) -> GLCapabilities:
    """Raise GLCapabilityError naming everything the context lacks; return caps if all is there."""
    missing = []
    for name, minimum, why in REQUIREMENTS:
        have = getattr(caps, name)
        if have < minimum:
            if name == "version_code":
                missing.append(f"OpenGL {have // 100}.{have % 100 // 10} < 4.1 core ({why})")
            else:
                missing.append(f"{name} = {have} < {minimum} ({why})")
    if missing:
        raise GLCapabilityError(
            f"this OpenGL context ({caps.renderer}) cannot run Speculum: " + "; ".join(missing))
    return caps


def create_headless_context() -> moderngl.Context:
    """An offscreen OpenGL 4.1+ core context through EGL (no display needed)."""
    try:
        ctx = moderngl.create_standalone_context(backend="egl", require=REQUIRED_VERSION)
    except Exception as exc:
        raise GLCapabilityError(
            f"could not create an OpenGL {REQUIRED_VERSION // 100}.{REQUIRED_VERSION % 100 // 10} core "
            f"context through EGL ({exc}); install Mesa's EGL (libegl1, libgl1-mesa-dri) or a GPU driver"
        ) from exc
    return ctx


def prepare_context(ctx: moderngl.Context) -> GLCapabilities:
    """Check the context and set the state the engine assumes everywhere."""
    caps = check_capabilities(GLCapabilities.read(ctx))
    ctx.gc_mode = None  # resources are released explicitly by the systems that own them
    return caps


def have_display() -> bool:
    """True when a windowing system is reachable (X11 or Wayland; always on macOS/Windows)."""
    if os.name == "nt" or os.uname().sysname == "Darwin":
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
