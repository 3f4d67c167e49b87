"""What an entity looks like: its mesh and the material properties the shader reads."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from pyglm import glm

from components.limits import (
    MAX_AIR_SCALE,
    MAX_ALTITUDE,
    MAX_DISPERSION,
    MAX_FILM_THICKNESS,
    MAX_IOR,
    MAX_SUBSURFACE_SCALE,
)
from components.tracking import (
    HALF_MAX,
    ComponentValueError,
    TrackedComponent,
    boolean,
    choice,
    color,
    finite,
    integer,
    vec3,
    warn_component,
)

# Assets are the engine's types (engine.assets.mesh.Mesh, engine.assets.texture_data.TextureData);
# components are the floor below it and import none of it: a field holding one is checked by
# the class's ASSET_KIND ("mesh", "texture"), and typed by these names.
Mesh = Any
TextureData = Any


@dataclass(eq=False)
class MeshRef(TrackedComponent):
    """The mesh an entity draws. Many entities may share one Mesh: they are instanced.

    ``visible`` False: drawn nowhere, and no shadow.  ``casts_shadows`` False: drawn, but in
    no light's shadow map (the sun's, a lamp's, a light's through a mirror or portal), as
    Unity's and Godot's per-renderer cast-shadows switch: a laser beam, a bulb beside its
    light's entity (a light's own entity's mesh casts none of that light's shadow anyway).
    It still receives shadows.  ``receives_shadows`` False: lit by every light as though
    nothing stood in its way (no map is looked up for it: Unity's receive-shadows switch,
    three.js's ``receiveShadow``): a glowing sign, a sky dome, a surface whose own bumps would
    shadow it with acne.  It still casts shadows."""

    mesh: Mesh
    visible: bool = True
    casts_shadows: bool = True
    receives_shadows: bool = True

    def _validate(self, name: str, value: Any) -> Any:
        if name == "mesh" and getattr(type(value), "ASSET_KIND", None) != "mesh":
            raise ComponentValueError(f"MeshRef.mesh must be an engine.assets.mesh.Mesh, got {type(value).__name__}")
        world = getattr(self, "_world_ref", None)
        if name == "mesh" and world is not None:
            for entity in self._entities:  # a mirror's new mesh must have area, as at spawn
                world.check_invariants(entity, MeshRef, mesh=value)
        if name in ("visible", "casts_shadows", "receives_shadows"):
            return boolean(self, name, value)
        return value


MAX_NORMAL_SCALE = 16.0  # beyond this a normal map's bumps are all edge-on: a mistake, not a look
MAX_PARALLAX_DEPTH = 1.0  # metres a height map reaches below its surface (Material.parallax_depth)


MAX_SPECULAR_TINT = 10.0  # Material.specular_color: past it a dielectric's f0 is held at 1 in every channel anyway
MATERIAL_BLENDS = ("fade", "transparent")  # Material.blend: what a see-through material's alpha fades
MATERIAL_IMAGES = ("texture", "normal_map", "emissive_map", "metallic_roughness_map", "occlusion_map", "lightmap")
MAX_LIGHTMAP_INTENSITY = 1e4  # Material.lightmap_intensity: an 8-bit map's white at most this bright


@dataclass(eq=False)
class Material(TrackedComponent):
    """Surface parameters, linear colour space.

    ``texture`` multiplies ``color``; ``metallic`` and ``roughness`` drive the GGX
    specular; ``alpha`` in ``color`` is used by refraction (how much shows through).

    ``normal_map`` bends the shading normal per pixel: a tangent-space normal map in the
    OpenGL convention (RGB = normal x 0.5 + 0.5; red towards +U, green towards +V, blue out
    of the surface), read linearly, with ``normal_scale`` scaling its X and Y (glTF's
    ``normalTexture.scale``: 0 is flat).  It bends lighting, sky and probe reflections,
    refraction, and a mirror's reflection (the mirror's lookup of its reflected image
    follows the bent ray: engine/render/mirror_passes.py).  The tangent frame comes from
    the UVs' screen derivatives, so meshes need UVs, not tangents: red leans towards +U
    and green towards +V also where the UVs are mirrored (glTF's tangent w of -1), the same
    seen in a mirror as directly, and a double-sided back face's bent normal is minus its
    front's (as glTF and three.js have it: a bump on the front is a dent behind).

    On a mirror (limits): the UVs must be a linear map of the mirror's plane (a quad's
    are; otherwise the map, or the mirror, is refused when given: the mirror rule,
    ``engine/rules/mirror_rules.py``); the lookup is exact for distant things and shifts
    nearby ones too far; a bent lookup that would leave the mirror's own pixels keeps the
    flat one; and a mirror magnifies an 8-bit map's slope steps (1/127, about 0.45
    degrees), so gentle slopes show as terraces: give a mirror a 16-bit map (a 16-bit PNG
    file, or uint16 pixels: uploaded as RGBA16, steps of 1/32767) or slopes well above that.

    ``parallax_depth`` (metres, default 0: none) makes the normal map's alpha a height map
    (1 the surface, 0 that deep below it: Unity's and Unreal's height packed in the normal
    map; glTF has none) that each pixel's view ray is marched into (parallax occlusion
    mapping, Tatarchuk 2006: 6 to 16 steps by how grazing the view is, the last step's
    crossing found between its two ends), every map read where the ray meets it: bricks and
    cobbles stand out of a flat wall and hide what lies behind them as the eye moves, in
    mirrors and portals too.  The heights shadow themselves from the directional lights: from
    where the view ray meets them a ray towards the light is marched up to the surface in 6
    steps, and heights above it cut the light, so a low sun throws each brick's shadow across
    the mortar (the lamps' light is not marched: a march each).  The surface itself stays flat
    (its outline, depth and the shadows it casts on other things are the mesh's).  At most
    ``MAX_PARALLAX_DEPTH`` (1 m); it needs a ``normal_map``.

    ``metallic_roughness_map`` (glTF's ``metallicRoughnessTexture``, read linearly): its
    green channel multiplies ``roughness`` and its blue channel ``metallic`` per pixel; the
    blue channel also scales a sky or probe reflection's mix (``Reflective.mix``), so the
    parts the map says are not metal keep their own shading (their environment reflection
    with it, whole).  ``emissive_map`` (glTF's
    ``emissiveTexture``, sRGB colour): with an ``Emissive`` component, the surface emits
    ``Emissive.power`` x the map's colour instead of ``power`` x its diffuse colour (glTF's
    ``emissiveFactor x emissiveTexture``, the factor being ``power``); without one it emits
    nothing, as a glTF emissive texture with a zero factor.  ``occlusion_map`` (glTF's
    ``occlusionTexture``, read linearly: its red channel) darkens the light that comes from
    all round (the sky's or a probe's ambient light, and a sky or probe reflection) in the
    creases a model's artist baked, by ``1 + occlusion_strength x (red - 1)``
    (``occlusionTexture.strength``: 0 leaves it out, 1 is the map as it is); the lights'
    own light is not darkened, as glTF says.  A map left out costs nothing: each is sampled
    only by a build of the scene shader for batches that have it.

    ``lightmap`` (three.js's ``lightMap``, Unity's and Godot's baked lightmaps; sRGB colour):
    the light from all round baked into an image, each texel the colour a white matte surface
    shows there (a Blender "Diffuse" bake without its colour), times ``lightmap_intensity``
    (three.js's ``lightMapIntensity``; an 8-bit image's white, so a brighter bake is saved
    divided by its largest value and that value given here).  It takes the place of the
    sky's, a probe's and an irradiance volume's diffuse light on the surface (what it was
    baked from: counted once), as a lightmapped object's in Unity and Godot; the lights'
    own light and shadows, the environment's reflections, the occlusion map and ambient
    occlusion still apply.  Bake it on the second UV set (``second_uv_maps=("lightmap",)``:
    a lightmap is unwrapped without overlaps, the colour texture may tile).

    ``second_uv_maps`` names the maps (of ``"texture"``, ``"normal_map"``,
    ``"emissive_map"``, ``"metallic_roughness_map"``, ``"occlusion_map"`` and ``"lightmap"``) that read the
    mesh's second UV set (``Mesh.second_uvs``, glTF's TEXCOORD_1) instead of its first, as a
    glTF map's ``texCoord`` 1, three.js's ``Texture.channel`` and Godot's "UV2" switches: a
    baked occlusion map or lightmap unwrapped once over a model whose colour texture tiles,
    or a decal sheet laid over a repeating one.  Refused when given for a mesh without a
    second set (``engine/rules/uv_rules.py``).  Only batches with such a map pay for it (a
    build of the scene shaders that reads the second set).

    ``alpha_cutoff`` (None: off) makes the material a cutout, as glTF's ``alphaMode: MASK``
    with its ``alphaCutoff``, three.js's ``alphaTest``, Unity's alpha clipping and Godot's
    alpha scissor: where the alpha (``color``'s times ``texture``'s) is below it, nothing
    is drawn, in every view and in every light's shadow map (leaves, a fence, a grate);
    elsewhere the surface is opaque whatever its alpha, so it is not blended and needs no
    sorting.  Its texture's mip levels keep its coverage at the cutoff
    (``engine/render/cutout_mips.py``), so a far tree keeps its leaves.  Not on a Mirror or
    Portal (refused: a surface's claim of its pixels is drawn whole; put the cutout on an
    entity in front of it).

    ``environment_reflection`` scales what the surface reflects of the light from all round
    (the captures of the reflection probes whose influence boxes hold its position, blended,
    and the sky), as every engine's default material reflects it: 1 (the default) is the
    physical amount for its
    ``metallic``, ``roughness`` and the angle it is seen at (the split-sum GGX reflection:
    a dielectric reflects 4% head on and most at grazing angles, a metal its colour
    everywhere), 0 none (Unity's "Environment Reflections" off), a share between.  Not read
    where a ``Reflective``, a ``Mirror`` or a ``Portal`` decides what the surface reflects
    (with a metallic-roughness map, the parts it says are not metal reflect the environment
    whole under a Reflective).

    ``double_sided`` draws both faces of each triangle (glTF's ``doubleSided``, three.js's
    ``side: DoubleSide``, Unity's render face "Both"): a leaf, a fence or a sheet of paper
    seen from behind, lit as its back (the normal turned towards the eye).  Otherwise the
    back faces are culled, as a closed mesh wants.  Shadows are cast by both faces either
    way.  Not on a Mirror or Portal (refused: a surface is seen from its front).

    ``blend`` says what a see-through material's alpha (``color``'s, times ``texture``'s,
    below 1: the transparent slot) fades.  ``"fade"`` (the default, glTF's BLEND, Unity's
    Fade mode): everything, its highlights and reflections too, so at alpha 0 it is gone.
    ``"transparent"`` (Unity's Transparent mode, Filament's transparent blending): only the
    light it scatters, its diffuse colour; the lights' highlights, its reflection of the light
    from all round and a ``Reflective``'s reflection stay whole over what shows through, as on
    a window pane or clear plastic, whose alpha is how much of its colour covers what is behind,
    and so does an ``Emissive``'s light (a lit sign on glass, a neon tube: Unity's Standard
    shader adds emission after its premultiply).  (Refraction, what lies behind bent and
    tinted: ``Refractive``.)

    ``clearcoat`` (0 to 1, default 0: none) lays a clear varnish over the material, as on car
    paint, lacquered wood or a glazed tile (glTF's ``KHR_materials_clearcoat``, Filament's,
    three.js's and Unreal's clear coat): a colourless layer of index 1.5 (4% head on) with a
    GGX lobe of its own, ``clearcoat_roughness`` (default 0: polished), reflecting the
    lights and the light from all round sharply over a rough or coloured base, which keeps
    what the coat's Fresnel reflection leaves (1 - clearcoat x F at the angle it is seen).
    The coat follows the mesh's own surface, not a normal map's bumps (a smooth varnish
    over a textured base).

    ``sheen_color`` (linear RGB, each 0 to 1; default black: none) and ``sheen_roughness``
    (0 to 1, default 0) give the material the soft sheen of cloth, velvet or dust seen at
    grazing angles (glTF's ``KHR_materials_sheen``, Filament's and three.js's sheen): a
    layer whose microfibres scatter light back at the rims (the "Charlie" distribution of
    Estevez and Kulla, 2017, with Neubelt's visibility, as Filament draws it), over the
    material, which keeps what the sheen's own albedo at that angle takes
    (1 - max(sheen_color) x E(n.v)).  Lit by every light, through mirrors and portals too,
    and by the light from all round.

    ``anisotropy`` (0 to 1, default 0: none) stretches the lights' highlights and the
    reflection along one direction of the surface, as on brushed metal, a vinyl record or
    hair (glTF's ``KHR_materials_anisotropy``, Filament's and three.js's anisotropy): the
    roughness along that direction is mix(roughness^2, 1, anisotropy^2) in GGX's alpha, across
    it roughness^2.  ``anisotropy_direction`` (degrees, default 0) is that direction, turned
    from the texture's u axis (the UVs' +u on the surface) counter-clockwise towards +v: a
    mesh without varying UVs takes some direction in its surface.

    ``iridescence`` (0 to 1, default 0: none) lays a thin film over the material whose
    colours shift with the angle it is seen at, as a soap bubble, an oil slick, a beetle's
    shell or heat-tinted titanium (glTF's ``KHR_materials_iridescence``, Belcour and Barla's
    thin-film model, as Filament's and three.js's): ``iridescence_ior`` is the film's index
    (default 1.3), ``iridescence_thickness`` its thickness in nanometres (default 400; the
    colours cycle every few hundred nm, none below about 50).

    ``reflectance`` (0 to 1, default 0.5) is how much a non-metal reflects head on, as
    Filament's and Godot's ``specular``/``reflectance`` knob: f0 = 0.16 x reflectance^2, so
    0.5 is the 4% of glass, plastic and most things (index 1.5), 0.35 water's 2%, 1 the 16% of
    a gem; the Fresnel effect raises it towards grazing angles whatever it is.  A metal
    reflects its colour instead.  glTF's ``KHR_materials_ior`` and ``KHR_materials_specular``
    set it.  ``specular_color`` (linear RGB, each 0 to 10, default white) tints that head-on
    reflection, each channel held at 1 (glTF's ``specularColorFactor``, three.js's
    ``specularColor``): the coloured sheen of some plastics, lacquers and fabrics, whose
    highlights are not the light's colour.

    ``diffuse_transmission`` (0 to 1, default 0: none) lets that share of the light a
    surface scatters pass through it, as thin leaves, paper, a lampshade or a curtain do
    (glTF's ``KHR_materials_diffuse_transmission``, Godot's backlight, Unity's translucency):
    lit from behind, its front glows with ``diffuse_transmission_color`` (linear RGB, each 0
    to 1, default white: what it lets through, not tinted by its colour) times that light's
    share, scattered evenly (the back's Lambert, with the back's shadows), and it scatters
    ``1 - diffuse_transmission`` of the light in front.  Lit by the sun and the lamps and the
    light from all round behind it (light through mirrors and portals lights its front only).
    Give a leaf or a sheet ``double_sided`` as well: each side is then the other's back.

    ``subsurface`` (0 to 1, default 0: none) is the share of the diffuse light that wanders
    under the surface before it leaves, as in skin, wax, marble, jade or milk (Blender's
    Principled BSDF's subsurface weight, Godot's subsurface scattering, Unity HDRP's and
    Unreal's subsurface profiles): where the surface curves, its shading softens towards the
    terminator and wraps past it, in the colour of the light that travels furthest.
    ``subsurface_radius`` (linear RGB, each 0 to 1, default ``(1.0, 0.2, 0.1)``: skin's, red
    travelling furthest) times ``subsurface_scale`` (metres, 0 to ``MAX_SUBSURFACE_SCALE``,
    default 0.05) is each colour's distance (Burley's diffusion profile's d).  Pre-integrated:
    the light of a sphere curved as the surface is there (engine/render/subsurface.py), so a
    flat surface is lit as without it and a small one scatters more than a large one of the
    same material.  The sun's, lamps' and light through mirrors' and portals' diffuse light
    scatter, and so does the light from all round (the sky's, the probes', the irradiance
    volumes'; a lightmap's baked light does not).

    ``unlit`` (default False) draws the material's colour as it is, lit by nothing (glTF's
    ``KHR_materials_unlit``, Unity's Unlit shaders, three.js's ``MeshBasicMaterial``,
    Godot's unshaded mode): a sign, a backdrop, a baked or stylised asset whose texture
    already holds its light.  Its colour, texture and vertex colours, alpha, cutout and an
    ``Emissive``'s glow still apply, and so do a ``Reflective``'s or ``Refractive``'s slots and
    fog; no light, shadow, ambient or environment reflection reaches it.  It casts shadows
    as any other thing does.
    """

    color: Any = field(default_factory=lambda: glm.vec4(0.8, 0.8, 0.8, 1.0))
    texture: TextureData | None = None
    metallic: float = 0.0
    roughness: float = 0.5
    normal_map: TextureData | None = None
    normal_scale: float = 1.0
    parallax_depth: float = 0.0
    emissive_map: TextureData | None = None
    metallic_roughness_map: TextureData | None = None
    occlusion_map: TextureData | None = None
    occlusion_strength: float = 1.0
    lightmap: TextureData | None = None
    lightmap_intensity: float = 1.0
    environment_reflection: float = 1.0
    alpha_cutoff: float | None = None
    double_sided: bool = False
    blend: str = "fade"
    clearcoat: float = 0.0
    clearcoat_roughness: float = 0.0
    unlit: bool = False
    reflectance: float = 0.5
    sheen_color: Any = field(default_factory=lambda: glm.vec3(0.0))
    sheen_roughness: float = 0.0
    anisotropy: float = 0.0
    anisotropy_direction: float = 0.0
    iridescence: float = 0.0
    iridescence_ior: float = 1.3
    iridescence_thickness: float = 400.0
    second_uv_maps: tuple[str, ...] = ()
    specular_color: Any = field(default_factory=lambda: glm.vec3(1.0))
    diffuse_transmission: float = 0.0
    diffuse_transmission_color: Any = field(default_factory=lambda: glm.vec3(1.0))
    subsurface: float = 0.0
    subsurface_radius: Any = field(default_factory=lambda: glm.vec3(1.0, 0.2, 0.1))
    subsurface_scale: float = 0.05

    def _validate(self, name: str, value: Any) -> Any:
        if name == "second_uv_maps":
            value = second_uv_names(value)
            world = getattr(self, "_world_ref", None)
            if world is not None and value:
                for entity in self._entities:  # its mesh must have a second UV set, as at spawn
                    world.check_invariants(entity, Material, second_uv_maps=value)
            return value
        if name == "blend":
            return choice(self, name, value, MATERIAL_BLENDS)
        if name == "alpha_cutoff":
            if value is None:
                return None
            value = finite(self, name, value, low=0.0, high=1.0)
            world = getattr(self, "_world_ref", None)
            if world is not None:
                for entity in self._entities:  # not on a mirror or a portal, as at spawn
                    world.check_invariants(entity, Material, alpha_cutoff=value)
            return value
        if name == "color":
            return color(self, name, value)
        if name in ("metallic", "roughness"):
            return finite(self, name, value, low=0.0, high=1.0)
        if name == "normal_scale":
            return finite(self, name, value, low=0.0, high=MAX_NORMAL_SCALE)
        if name == "parallax_depth":
            value = finite(self, name, value, low=0.0, high=MAX_PARALLAX_DEPTH)
            if value > 0.0:
                _say_flat_heights(getattr(self, "normal_map", None), value)
            return value
        if name in ("occlusion_strength", "environment_reflection", "clearcoat", "clearcoat_roughness", "reflectance",
                    "sheen_roughness", "anisotropy", "iridescence", "diffuse_transmission", "subsurface"):
            return finite(self, name, value, low=0.0, high=1.0)
        if name == "subsurface_scale":
            return finite(self, name, value, low=0.0, high=MAX_SUBSURFACE_SCALE)
        if name == "subsurface_radius":
            # (a share of subsurface_scale each: the scale says how far)
            return vec3(self, name, value, low=0.0, high=1.0, why=" (each colour's share of subsurface_scale)")
        if name == "lightmap_intensity":
            return finite(self, name, value, low=0.0, high=MAX_LIGHTMAP_INTENSITY)
        if name == "iridescence_ior":
            return finite(self, name, value, low=1.0, high=MAX_IOR)
        if name == "iridescence_thickness":
            return finite(self, name, value, low=0.0, high=MAX_FILM_THICKNESS)
        if name == "anisotropy_direction":
            return finite(self, name, value, low=-360.0, high=360.0)
        if name == "specular_color":
            return vec3(self, name, value, low=0.0, high=MAX_SPECULAR_TINT)
        if name == "diffuse_transmission_color":
            # (what passes: more than arrives would make light)
            return vec3(self, name, value, low=0.0, high=1.0)
        if name == "sheen_color":
            # (a layer's albedo: more than 1 would reflect more light than arrives)
            return vec3(self, name, value, low=0.0, high=1.0)
        if name == "unlit":
            return boolean(self, name, value)
        if name == "double_sided":
            value = boolean(self, name, value)
            world = getattr(self, "_world_ref", None)
            if world is not None and value:
                for entity in self._entities:  # not on a mirror or a portal, as at spawn
                    world.check_invariants(entity, Material, double_sided=value)
            return value
        if name in MATERIAL_IMAGES and value is not None:
            if getattr(type(value), "ASSET_KIND", None) != "texture":
                raise ComponentValueError(
                    f"Material.{name} must be an engine.assets.texture_data.TextureData, got {type(value).__name__}")
            if name == "normal_map" and getattr(self, "parallax_depth", 0.0) > 0.0:
                _say_flat_heights(value, self.parallax_depth)
            world = getattr(self, "_world_ref", None)
            if name == "normal_map" and world is not None:
                for entity in self._entities:  # a mirror's UVs must allow it, as at spawn
                    world.check_invariants(entity, Material, normal_map=value)
        return value


def _say_flat_heights(normal_map: Any, depth: float) -> None:
    """``Material.parallax_depth`` reads the normal map's alpha as heights: said (a
    ComponentWarning) when there is no normal map, or its alpha is one value everywhere (an
    RGB file's is): the depth then changes nothing."""
    if normal_map is None:
        warn_component(f"Material.parallax_depth = {depth:g} does nothing without a normal_map (its alpha holds "
                       "the heights)")
    elif np.ptp(np.asarray(normal_map.pixels)[..., 3]) == 0:
        warn_component(f"Material.parallax_depth = {depth:g}: the normal map {normal_map.name!r} has no heights in "
                       "its alpha (one value everywhere), so nothing is marched; put the heights in its alpha "
                       "(1 the surface, 0 the deepest)")


def second_uv_names(value: Any) -> tuple[str, ...]:
    """``Material.second_uv_maps`` checked: names of its map fields (``MATERIAL_IMAGES``),
    each once, kept in that order."""
    names = (value,) if isinstance(value, str) else value
    try:
        names = tuple(names)
    except TypeError:
        raise ComponentValueError(f"Material.second_uv_maps must be a list of map names, got {value!r}") from None
    unknown = [n for n in names if not isinstance(n, str) or n not in MATERIAL_IMAGES]  # (an array: no ==)
    if unknown:
        raise ComponentValueError(f"Material.second_uv_maps names {unknown[0]!r}, which is not one of its maps "
                                  f"({', '.join(MATERIAL_IMAGES)})")
    if len(set(names)) != len(names):
        raise ComponentValueError(f"Material.second_uv_maps names a map twice: {list(names)!r}")
    return tuple(n for n in MATERIAL_IMAGES if n in names)


ALBEDO_UV_BIT = 1 << MATERIAL_IMAGES.index("texture")  # the albedo map's bit in ``second_uv_mask``


def second_uv_mask(material: Material | None) -> int:
    """The maps of ``material`` that are set and read the second UV set, as bits (bit i:
    ``MATERIAL_IMAGES[i]``): what the scene shaders' SECOND_UV_MAPS build reads
    (``shaders/include/uv_sets.glsl``); 0: none."""
    if material is None or not material.second_uv_maps:
        return 0
    return sum(1 << i for i, n in enumerate(MATERIAL_IMAGES)
               if n in material.second_uv_maps and getattr(material, n) is not None)


@dataclass(eq=False)
class Emissive(TrackedComponent):
    """The surface emits ``power`` x its diffuse colour (an emissive term added after lighting)."""

    power: float = 1.0

    def _validate(self, name: str, value: Any) -> Any:
        if name == "power":
            return finite(self, name, value, low=0.0, high=HALF_MAX)  # emitted colour lands in half floats
        return value


REFLECT_MODES = ("skybox", "planar", "cube", "portal")


@dataclass(eq=False)
class Reflective(TrackedComponent):
    """The surface reflects its environment.

    ``mix`` is how much of the final colour is the reflection: None means 1.0 for an
    untextured surface (chrome) and ``0.5`` for a textured one (a 50/50 texture/reflection mix).
    ``tint`` multiplies the reflected light.
    """

    mode: str = "skybox"
    mix: float | None = None
    tint: Any = field(default_factory=lambda: glm.vec4(1.0))

    def _validate(self, name: str, value: Any) -> Any:
        if name == "mode":
            return choice(self, name, value, REFLECT_MODES)
        if name == "mix" and value is not None:
            return finite(self, name, value, low=0.0, high=1.0)
        if name == "tint":
            return color(self, name, value)
        return value


def reflection_mix(reflective: Reflective, material: Material | None) -> float:
    """How much of the final colour is the reflection: ``reflective.mix``, or where it is None
    ``automatic_mix``."""
    return reflective.mix if reflective.mix is not None else automatic_mix(material)


def automatic_mix(material: Material | None) -> float:
    """A reflection's mix left to the engine: 1.0 for an untextured surface (chrome), 0.5 for
    a textured one (a 50/50 mix of texture and reflection)."""
    return 0.5 if material is not None and material.texture is not None else 1.0


@dataclass(eq=False)
class Refractive(TrackedComponent):
    """Light from behind bends through the surface (Snell's law with Schlick's Fresnel approximation).

    The environment seen along the refracted ray is weighted by Fresnel transmittance and
    blended with the surface colour by the material's alpha (alpha 0 = clear glass); the
    surface's reflection of the environment (``Material.environment_reflection``: the
    reflected share, Fresnel's F, of the probe its refraction reads, or of the sky) lies over
    both whatever the alpha, so clear glass shows bright rims where it reflects most.
    ``solid`` False (the default): a thin surface, the ray refracted once where it enters (a
    bubble or a window's pane seen as one surface).  True: a solid glass ball, the ray
    refracted in, carried along its chord through the sphere and refracted out (a ball lens,
    worked out in closed form in the shader: ``solid_sphere_exit`` in shaders/scene.frag),
    so the ball shows the room behind it upside down and more strongly bent; exact for a
    sphere mesh, an approximation on other shapes.
    ``dispersion`` (0, the default: none; at most MAX_DISPERSION) splits the colours as a
    prism or a diamond does (glTF's ``KHR_materials_dispersion``: 20 / the glass's Abbe
    number, about 0.3 for window glass, 1 for flint glass, 0.4 for diamond): each channel
    is bent by its own index, ``ior`` -/+ (ior - 1) x 0.025 x dispersion for red and blue
    (three.js's spread), green by ``ior`` itself.
    ``screen`` (True, the default): in the camera's view and every mirror and portal view
    below it, what lies behind along the refracted ray is what that view drew there (a
    screen-space refraction, as three.js's transmission, Godot's refraction and HDRP's
    screen-space refraction read the frame behind the glass): the ray is marched across a
    copy of the view's colour and depth taken after its opaque surfaces, sky, mirrors and
    portals and before its glass (``engine/render/screen_refraction.py``), so a box behind a
    pane shows through it, bent, and a ray that runs on over the sky the view drew shows that
    sky; where the ray leaves the view, passes behind what is drawn or finds nothing, the
    probe's or sky's image stays, with a fade between.  Its own reflection is found the same
    way (the reflected ray marched across the copy).
    Glass seen through glass is drawn first, in a layer of its own, and the nearer reads a
    copy that holds it (farthest first, at most MAX_REFRACTION_LAYERS deep), see-through
    things behind it show through it (where none of them meeting it lies in front), a rough surface
    reads a blurrier level of the copy, and probe captures read the probe or sky.
    False: the probe's or sky's image only (cheaper: no copy, no march).
    """

    ior: float = 1.5
    solid: bool = False
    dispersion: float = 0.0
    screen: bool = True

    def _validate(self, name: str, value: Any) -> Any:
        if name == "ior":
            return finite(self, name, value, low=1.0, high=MAX_IOR)
        if name == "solid":
            return boolean(self, name, value)
        if name == "dispersion":
            return finite(self, name, value, low=0.0, high=MAX_DISPERSION)
        if name == "screen":
            return boolean(self, name, value)
        return value


# Where a generated sky's sun stands when it follows no light (``Skybox.sun_direction``):
# high in the -z half of the sky, towards the sun.
SKY_MODELS = ("gradient", "atmosphere")   # Skybox.model
DEFAULT_SUN_DIRECTION: tuple[float, float, float] = tuple(glm.normalize(glm.vec3(0.4, 0.6, -0.7)))


@dataclass(eq=False)
class Skybox(TrackedComponent):
    """The world's background cube map: six face images, or a generated gradient sky.  A world
    has one: a second is refused (``light_rules.check_one_sky``); change its fields instead.

    ``faces`` is None (generate from the colours below) or six HxWx3 float arrays in GL
    face order +X, -X, +Y, -Y, +Z, -Z, linear colour: a photographed or rendered sky from an
    equirectangular panorama (a Radiance ``.hdr`` or OpenEXR ``.exr`` HDRI, or a PNG or JPEG) is
    ``engine.assets.panorama.sky_faces_from_file(path, face_size, yaw)``.  A generated sky's background is
    drawn from the colours per pixel (``engine/render/sky.py``); ``face_size`` is the side of
    the cube map made from them, which reflections, refraction and the sky's light read.

    ``sun_direction`` (towards the sun): None, the default, puts the generated sky's sun
    disc and its warm glow where the world's brightest ``DirectionalLight`` comes from (the
    light's ``direction`` negated; ``engine.rules.light_rules.sky_sun``), the disc
    ``sun_color`` times that light's colour, as Unity's sun source and Godot's procedural
    sky do, so the disc, a chrome ball's glint of it and the shadows agree.  While that light
    turns or recolours the sky pass follows it every frame; the cube map and the sky's light
    (drawn on the GPU and in closed form: ``engine/render/sky_bake.py``) follow within a
    degree, and exactly once it stands still.
    With no lit ``DirectionalLight`` the sun stands at ``DEFAULT_SUN_DIRECTION``.  A vector
    pins the sun there, whatever the lights do.

    ``model``: "gradient" (the default: ``zenith``, ``horizon`` and ``ground`` colours, a warm
    glow about the sun) or "atmosphere", a physically based sky (``engine/render/atmosphere.py``:
    Rayleigh and Mie scattering, ozone and multiple scattering, Hillaire 2020, as Unreal's
    SkyAtmosphere, Godot's PhysicalSkyMaterial and three.js's Sky): blue overhead at noon,
    white at the horizon, red round a low sun, dark once it has set, all from where the sun
    stands.  Its sky is ``sun_color`` (times the light's colour) scattered by the air, the
    disc that light dimmed by the air; ``zenith`` and ``horizon`` are unused and ``ground`` is
    the ground's albedo (lit by the sun and the sky below the horizon).  ``rayleigh`` and
    ``haze`` (0 to ``MAX_AIR_SCALE``, 1: Earth's clear air) scale the air's molecules (thicker:
    a deeper blue, redder sunsets) and its aerosols (a whiter sky, a wider glow round the
    sun).  ``altitude`` (metres above sea level, 0 to ``MAX_ALTITUDE``, default 200) is how
    high the level stands: the air above it thinner the higher (a mountain's sky a deeper,
    darker blue, its sun whiter and brighter at sunset; the level's own heights are nothing to
    the air's kilometres, so the whole level takes it).  With ``tints_sunlight`` (the default)
    the DirectionalLight the sky follows is dimmed and reddened by the same air on its way
    down, as Unreal's atmosphere sun light:
    its ``color`` is its light with the sun overhead, and a low sun lights the world orange
    (a pinned ``sun_direction`` follows no light and tints none).  An atmosphere's ``faces``
    are the space beyond its air (stars, a galaxy: ``engine.assets.star_field.star_faces``),
    shown through it where it lets them through and is itself dark: at night, fading towards
    the horizon.

    ``moon_color`` (linear RGB): the disc of a ``DirectionalLight`` whose ``body`` is "moon",
    lit head on, times that light's colour; drawn by a generated sky (the gradient's and the
    atmosphere's, dimmed by its air) lit from the sky's sun, so it waxes and wanes.
    """

    zenith: Any = field(default_factory=lambda: glm.vec4(0.10, 0.25, 0.65, 1.0))
    horizon: Any = field(default_factory=lambda: glm.vec4(0.65, 0.75, 0.90, 1.0))
    ground: Any = field(default_factory=lambda: glm.vec4(0.18, 0.14, 0.10, 1.0))
    sun_direction: Any = None
    sun_color: Any = field(default_factory=lambda: glm.vec4(6.0, 5.4, 4.2, 1.0))
    moon_color: Any = field(default_factory=lambda: glm.vec4(1.0, 1.0, 1.05, 1.0))
    face_size: int = 128
    faces: Any = None
    model: str = "gradient"
    rayleigh: float = 1.0
    haze: float = 1.0
    altitude: float = 200.0
    tints_sunlight: bool = True

    def _validate(self, name: str, value: Any) -> Any:
        if name in ("zenith", "horizon", "ground", "sun_color", "moon_color"):
            return color(self, name, value)
        if name == "model":
            return choice(self, name, value, SKY_MODELS)
        if name in ("rayleigh", "haze"):
            return finite(self, name, value, low=0.0, high=MAX_AIR_SCALE)
        if name == "altitude":
            return finite(self, name, value, low=0.0, high=MAX_ALTITUDE)
        if name == "tints_sunlight":
            return boolean(self, name, value)
        if name == "sun_direction":
            from components.tracking import direction

            return None if value is None else direction(self, name, value)
        if name == "face_size":
            return integer(self, name, value, low=4, high=2048)
        if name == "faces" and value is not None:
            return _sky_faces(value)
        return value


def _sky_faces(value: Any) -> np.ndarray:
    """Six square HxWx3 linear images as one (6, n, n, 3) float32 array (checked here, not at render)."""
    try:
        with np.errstate(over="ignore"):  # past float32 becomes inf, refused just below
            faces = np.asanyarray(value, np.float32)   # (a panorama's SkyFaces keeps its source)
    except (TypeError, ValueError, OverflowError):
        raise ComponentValueError(
            f"Skybox.faces must be six square HxWx3 float images, got {type(value).__name__}") from None
    if faces.ndim != 4 or faces.shape[0] != 6 or faces.shape[1] != faces.shape[2] or faces.shape[3] != 3 \
            or not 1 <= faces.shape[1] <= 2048:
        raise ComponentValueError(
            f"Skybox.faces must be six square HxWx3 images (side 1..2048), got shape {faces.shape}")
    if not np.isfinite(faces).all() or faces.min() < 0.0 or faces.max() > 65504.0:
        raise ComponentValueError("Skybox.faces must hold finite linear colours in [0, 65504] (half floats)")
    return faces
