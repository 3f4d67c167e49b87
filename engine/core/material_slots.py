"""Subroutine-style material dispatch: the slots of the scene fragment shader.

GLSL subroutines are not reachable through moderngl 5.13 (and GL resets them on every
program bind), so the shader has the same shape written by hand: each slot is a function
that switches on a per-instance index to one of its variants.  This module is the single
source of the indices: the shader library turns it into ``#define``s, and the material
system writes the chosen index of each slot into every instance record.
"""
from __future__ import annotations

from enum import IntEnum


class EmissiveVariant(IntEnum):
    NONE = 0
    EMISSIVE = 1


class RefractVariant(IntEnum):
    NONE = 0
    ENVIRONMENT = 1  # a thin surface: refracted once, where the ray enters
    SOLID = 2        # a solid ball: refracted in and out (Refractive.solid)


class ReflectVariant(IntEnum):
    NONE = 0
    SKYBOX = 1
    PLANAR = 2
    CUBE = 3
    PORTAL = 4


SLOTS: dict[str, type[IntEnum]] = {
    "EMISSIVE": EmissiveVariant,
    "REFRACT": RefractVariant,
    "REFLECT": ReflectVariant,
}


def glsl_defines() -> dict[str, str]:
    """``EMISSIVE_NONE`` -> ``0u`` and so on, for every slot variant."""
    return {f"{slot}_{variant.name}": f"{int(variant)}u" for slot, enum in SLOTS.items() for variant in enum}
