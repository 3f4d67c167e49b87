"""A test-only check of ``texelFetch`` coordinates: out of a texture's level size, GL 4.1
core (no robust buffer access) leaves what the fetch returns undefined (GLSL 4.10 8.9.2,
GL 4.1 2.11.9 / 3.8.?: "results are undefined").  llvmpipe returns zeros (or clamps); a GPU
may return garbage or another texture's texels.

``poisoned_fetches(ctx)`` wraps ``moderngl.Context.program`` for as long as it is entered
(never in product code paths) and builds every program with a prelude after its
``#version`` line that turns each ``texelFetch(s, p, lod)`` into a bounded fetch: ``p``
inside ``textureSize(s, lod)`` reads the texel as before, outside it returns a poison
value (``constant``: a float far from any colour, a uint that is no entity, view or marker
id; ``edge``: the texel at the nearest edge, a plausible id where llvmpipe's zero is none).  A
frame drawn with it is bit for bit the frame drawn without it unless some fetch left its
texture and its value mattered (a fetch outside whose pixel is discarded, or whose value a
select throws away, changes nothing, as it should not): the second path of the test.
"""
from __future__ import annotations

import contextlib
from collections.abc import Iterator

import moderngl

from tests.support import programs_linked_anew

POISON_FLOAT = 4093.0          # rgb far above any colour (white after the tone curve), alpha too
POISON_UINT = 0x5EEDF00D       # no entity id, node index or NO_END_IMAGE (0xFFFFFFFF)

_CONSTANT = {"vec4": f"vec4({POISON_FLOAT})", "uvec4": f"uvec4({POISON_UINT}u)", "ivec4": f"ivec4({POISON_UINT})"}
_SAMPLERS = (("vec4", "sampler2D"), ("uvec4", "usampler2D"), ("ivec4", "isampler2D"))
MODES = ("constant", "edge")


def _prelude(mode: str) -> str:
    """The bounded fetches: outside, ``constant`` returns the poison, ``edge`` the texel at
    the nearest edge (what a driver clamping its coordinates, or one reading the neighbouring
    texels of memory, hands back: a plausible id where the poison is none)."""
    def outside(kind: str) -> str:
        return _CONSTANT[kind] if mode == "constant" else "texelFetch(s, clamp(p, ivec2(0), size - 1), lod)"
    functions = "".join(
        f"{kind} bounded_fetch({sampler} s, ivec2 p, int lod) {{\n"
        f"    ivec2 size = textureSize(s, lod);\n"
        f"    return all(greaterThanEqual(p, ivec2(0))) && all(lessThan(p, size)) ? texelFetch(s, p, lod) : "
        f"{outside(kind)};\n}}\n" for kind, sampler in _SAMPLERS)
    return f"\n{functions}#define texelFetch(s, p, lod) bounded_fetch(s, p, lod)\n"


def with_prelude(source: str, mode: str = "constant") -> str:
    """``source`` (a whole stage, ``#version`` first) with the bounded fetches of ``mode``."""
    first, _, rest = source.partition("\n")
    assert first.startswith("#version"), first
    return f"{first}\n{_prelude(mode)}{rest}"


@contextlib.contextmanager
def poisoned_fetches(mode: str = "constant") -> Iterator[list[str]]:
    """Inside: every program made has bounded fetches of ``mode`` (``MODES``, module
    docstring); yields the list of stages rewritten (those whose source calls ``texelFetch``)."""
    assert mode in MODES, mode
    make_program = moderngl.Context.program
    rewritten: list[str] = []
    names = ("vertex_shader", "fragment_shader", "geometry_shader")

    def poisoned_program(self, *args, **kwargs):
        given = {**dict(zip(names, args, strict=False)), **kwargs}
        for name in names:
            source = given.get(name)
            if source and "texelFetch" in source:
                given[name] = with_prelude(source, mode)
                rewritten.append(name)
        return make_program(self, **given)

    moderngl.Context.program = poisoned_program
    try:
        with programs_linked_anew():  # every program through the hook, none handed on
            yield rewritten
    finally:
        moderngl.Context.program = make_program
