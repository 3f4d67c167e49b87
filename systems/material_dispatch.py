"""Choosing each instance's material variants from its components (what GLSL subroutine
selection would do, done on the CPU once per change instead of once per draw)."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from pyglm import glm

from components import Emissive, Material, Mirror, Portal, Reflective, Refractive
from components.rendering import reflection_mix
from engine.core.material_slots import EmissiveVariant, ReflectVariant, RefractVariant

_REFLECT_MODES = {
    "skybox": ReflectVariant.SKYBOX, "planar": ReflectVariant.PLANAR,
    "cube": ReflectVariant.CUBE, "portal": ReflectVariant.PORTAL,
}
DEFAULT_MATERIAL = Material()


@dataclass(frozen=True)
class MaterialChoice:
    """One instance's variant per slot and the numbers those variants read."""

    emissive: EmissiveVariant
    refract: RefractVariant
    reflect: ReflectVariant
    color: glm.vec4
    surface: tuple[float, float, float, float]  # metallic, roughness, emissive power, normal-map scale
    reflect_params: tuple[float, float, float, float]  # mix (no reflect slot: the environment's share), ior, -, -
    tint: glm.vec4


def choose_material(material: Material | None, emissive: Emissive | None,
                    reflective: Reflective | None, refractive: Refractive | None,
                    mirror: Mirror | None = None, portal: Portal | None = None,
                    probe: bool = False) -> MaterialChoice:
    """``probe``: a reflection probe serves the object (``engine/rules/probe_rules.py``); without
    one, ``Reflective("cube")`` reflects the sky."""
    material = material or DEFAULT_MATERIAL
    emissive_variant = EmissiveVariant.EMISSIVE if emissive is not None and emissive.power > 0 else \
        EmissiveVariant.NONE
    reflect_variant = _REFLECT_MODES[reflective.mode] if reflective is not None else ReflectVariant.NONE
    mix = 0.0
    tint = glm.vec4(1.0)
    if reflective is not None:
        mix = reflection_mix(reflective, material)
        tint = reflective.tint
    if portal is not None:
        # Drawn flat in its closed colour; an open portal's view is composited over it.
        reflect_variant = ReflectVariant.PORTAL
        tint = portal.closed_color
    elif mirror is not None and mirror.enabled:
        # The ReflectionSystem blends the mirror's image over its own shading afterwards.
        reflect_variant = ReflectVariant.PLANAR
    elif reflect_variant == ReflectVariant.PLANAR:
        reflect_variant = ReflectVariant.SKYBOX  # planar needs a Mirror; the sky is the fallback
    elif reflect_variant == ReflectVariant.CUBE and not probe:
        reflect_variant = ReflectVariant.SKYBOX
    if reflect_variant == ReflectVariant.NONE:
        mix = material.environment_reflection  # the environment's reflection (scene.frag environment_specular)
    return MaterialChoice(
        emissive=emissive_variant,
        refract=(RefractVariant.NONE if refractive is None else
                 RefractVariant.SOLID if refractive.solid else RefractVariant.ENVIRONMENT),
        reflect=reflect_variant,
        color=material.color,
        surface=(material.metallic, material.roughness, emissive.power if emissive else 0.0, material.normal_scale),
        reflect_params=(mix, refractive.ior if refractive else 1.0, 0.0, 0.0),
        tint=tint,
    )


def dielectric_f0(material: Material | None) -> tuple[float, float, float]:
    """What a non-metal reflects head on, its batch's uniform: Filament's 0.16 x reflectance^2
    (``Material.reflectance``; 0.04, glass's and most things', at the default 0.5) times its
    tint (``Material.specular_color``), each channel held at 1."""
    m = material or DEFAULT_MATERIAL
    grey = 0.16 * m.reflectance ** 2
    return tuple(min(grey * float(c), 1.0) for c in m.specular_color)


def layer_uniforms(material: Material | None, refractive: Refractive | None) -> dict[str, Any]:
    """The batch arguments (``Renderer.batch_for``) of the material's optional layers, each its
    build's uniform and None (or 0) where the material has none, so it pays nothing for it: a
    clear coat (clearcoat, its roughness), a sheen (colour, roughness), diffuse transmission
    (its colour, its share), subsurface scattering (each channel's distance in metres, its
    share), anisotropy (strength, direction in radians), a thin film (iridescence, its index, its thickness in nm), what
    non-metals reflect head on, a refraction's dispersion, whether it refracts the view's own
    image (``Refractive.screen``: a batch drawn after the view's copy) and how deep the normal
    map's heights reach (its PARALLAX build's; 0 without a normal map)."""
    m = material or DEFAULT_MATERIAL
    return {"clearcoat": (m.clearcoat, m.clearcoat_roughness) if m.clearcoat > 0.0 else None,
            "sheen": (*m.sheen_color, m.sheen_roughness) if max(m.sheen_color) > 0.0 else None,
            "diffuse_transmission": (*m.diffuse_transmission_color, m.diffuse_transmission)
            if m.diffuse_transmission > 0.0 else None,
            "subsurface": (*(c * m.subsurface_scale for c in m.subsurface_radius), m.subsurface)
            if m.subsurface > 0.0 and m.subsurface_scale * max(m.subsurface_radius) > 0.0 else None,
            "anisotropy": (m.anisotropy, math.radians(m.anisotropy_direction)) if m.anisotropy > 0.0 else None,
            "iridescence": (m.iridescence, m.iridescence_ior, m.iridescence_thickness) if m.iridescence > 0.0 else None,
            "parallax_depth": m.parallax_depth if m.normal_map is not None else 0.0,
            "dielectric_f0": dielectric_f0(material),
            "dispersion": refractive.dispersion if refractive is not None else 0.0,
            "refracts_screen": refractive is not None and refractive.screen}
