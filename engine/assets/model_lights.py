"""The lights a glTF file carries (``KHR_lights_punctual``), read from its JSON and placed by
its node tree, for ``spawn_model`` to make into the engine's lights.

Blender, Maya's and 3ds Max's exporters write a level's lamps, spots and sun this way, so a
room modelled with its lights arrives lit, as three.js's, Godot's and Babylon.js's loaders
bring them in.  The extension's units are physical and the engine's lights take them as they
are: a point or spot light's ``intensity`` is candela (the engine's ``PointLight.intensity``:
light a square metre receives a metre away), a directional light's lux (the engine's
``DirectionalLight.intensity``: light a square metre facing it receives), both lighting a
Lambertian surface as albedo / pi times that; a file exported in watts-based units is as bright
as its exporter made it, and the camera's exposure (``Tonemap``) or ``spawn_model``'s
``light_scale`` brings it to the picture's range.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from pyglm import glm

from components.limits import MAX_FAR, MIN_SPOT_ANGLE
from components.tracking import HALF_MAX
from engine.core.errors import AssetError

LIGHT_KINDS = ("directional", "point", "spot")
# What the engine's lights have and KHR_lights_punctual has no word for, in a light's extras
# under this key (written by engine/assets/gltf_export.py), by name as the engine's light
# (PointLight for a point or spot, DirectionalLight for a directional one) has it, each with
# the kind of value it takes: a lamp's shape ("radius" metres: a sphere, "rectangle" [width,
# height] metres, "length" metres: a tube), its shadows, how many mirrors its light bounces
# off, a spot's cone past glTF's 90 degrees and its blend as given; a sun's shadow cascades,
# its disc, what body it is.  Their values are the components' to check (at spawn).
LIGHT_EXTRAS = "speculum"
LAMP_FIELDS = {"radius": "number", "rectangle": "pair", "length": "number", "shadows": "bool",
               "shadow_resolution": "integer", "shadow_softness": "number", "bounces": "integer",
               "spot_angle": "number", "spot_blend": "number", "contact_shadows": "bool", "volumetric": "number"}
SUN_FIELDS = {"shadows": "bool", "shadow_resolution": "integer", "shadow_softness": "number",
              "shadow_cascades": "integer", "shadow_distance": "number", "shadow_cascade_blend": "number",
              "angular_diameter": "number", "bounces": "integer", "body": "text"}
_KINDS_SAID = {"number": "a number", "integer": "a whole number", "bool": "true or false",
               "pair": "two numbers", "text": "a string"}
# A light without a range reaches as far as its inverse-square light stays above this many
# lux (1/256: under half a level of 255 on white paper at exposure 0), the engine's lights
# having a range to fade out at (their shadow cube's far plane, and what culls them).
RANGE_CUTOFF_LUX = 1.0 / 256.0
MIN_DEFAULT_RANGE = 1.0  # metres: the range of a light too dim to reach the cutoff


@dataclass
class ModelLight:
    """One light of a model file, where its node puts it.

    ``local`` is its node's transform in the model (as ``ModelPart.local``): the light at its
    origin, shining along its -Z (a spot's axis, a sun's direction), as glTF places lights.
    ``intensity`` as the file gives it (candela, lux for a directional light), ``range`` its
    distance cutoff or None (none given), ``inner_cone`` and ``outer_cone`` a spot's angles
    from its axis in radians (glTF's ``innerConeAngle``, ``outerConeAngle``)."""

    kind: str
    color: tuple[float, float, float]
    intensity: float
    range: float | None
    inner_cone: float
    outer_cone: float
    local: glm.mat4
    name: str
    node: int | None = None  # its node's index (what an animation moves)
    light: int | None = None  # its KHR_lights_punctual light's index (what an animation pointer names)
    # The engine's fields from its extras (LIGHT_EXTRAS: LAMP_FIELDS, SUN_FIELDS) as given.
    fields: dict[str, object] | None = None

    def reach(self, scale: float = 1.0) -> float:
        """The engine light's range: the file's, or where its light at ``scale`` falls to
        ``RANGE_CUTOFF_LUX`` (at least ``MIN_DEFAULT_RANGE``), at most ``MAX_FAR``."""
        if self.range is not None:
            return min(self.range, MAX_FAR)
        return min(max(math.sqrt(self.intensity * scale / RANGE_CUTOFF_LUX), MIN_DEFAULT_RANGE), MAX_FAR)

    def spot_angle(self) -> float:
        """The engine's ``PointLight.spot_angle``: the outer cone in degrees (180: all round)."""
        return math.degrees(self.outer_cone) if self.kind == "spot" else 180.0

    def spot_blend(self) -> float:
        """The engine's ``PointLight.spot_blend``: the share of the outer angle the light fades
        over, from the inner cone's edge to the outer's."""
        return (self.outer_cone - self.inner_cone) / self.outer_cone if self.kind == "spot" else 0.15


def read_gltf_lights(doc: dict | None) -> list[ModelLight]:
    """The lights the nodes of a glTF document's scene (its ``scene``, else its first) use,
    each placed by the product of its node's and its ancestors' transforms; a light used by
    two nodes is two lights.  A malformed light or node (a kind glTF does not have, a colour
    out of [0, 1], an intensity that is negative or past the engine's half floats, a spot's
    cones out of order, a light index the file does not have, a node transform that is not
    finite) is an AssetError naming it."""
    if not isinstance(doc, dict):
        return []
    extension = (doc.get("extensions") or {}).get("KHR_lights_punctual") \
        if isinstance(doc.get("extensions"), dict) else None
    defined = extension.get("lights") if isinstance(extension, dict) else None
    nodes = doc.get("nodes") if isinstance(doc.get("nodes"), list) else []
    used = [i for i, node in enumerate(nodes) if isinstance(node, dict) and _light_index(node) is not None]
    if not used:
        return []
    if not isinstance(defined, list):
        raise AssetError(f"node {used[0]} names a KHR_lights_punctual light, but the file defines none "
                         "(extensions.KHR_lights_punctual.lights)")
    lights = [_light(defined, i) for i in range(len(defined))]
    found: list[ModelLight] = []
    for index, matrix in placed_nodes(doc, nodes):
        light_index = _light_index(nodes[index])
        if light_index is None:
            continue
        if isinstance(light_index, bool) or not isinstance(light_index, int) or not 0 <= light_index < len(lights):
            raise AssetError(f"node {index} names KHR_lights_punctual light {light_index!r}, which the file does not "
                             f"have ({len(lights)} defined)")
        light = lights[light_index]
        found.append(ModelLight(light.kind, light.color, light.intensity, light.range, light.inner_cone,
                                light.outer_cone, glm.mat4(*matrix.astype(np.float32).T.ravel()), light.name,
                                index, light_index, light.fields))
    return found


def _light_index(node: dict) -> object:
    extensions = node.get("extensions")
    extension = extensions.get("KHR_lights_punctual") if isinstance(extensions, dict) else None
    return extension.get("light") if isinstance(extension, dict) else None


def finite_number(value: object) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _light(defined: list, index: int) -> ModelLight:
    """Light ``index`` of the extension's ``lights``, checked (placed at the origin)."""
    entry = defined[index]
    name = entry.get("name") if isinstance(entry, dict) and isinstance(entry.get("name"), str) else None
    what = f"KHR_lights_punctual light {index}" + (f" ({name!r})" if name else "")
    if not isinstance(entry, dict):
        raise AssetError(f"{what}: must be an object, got {entry!r}")
    kind = entry.get("type")
    if kind not in LIGHT_KINDS:
        raise AssetError(f"{what}: type must be one of {LIGHT_KINDS}, got {kind!r}")
    color = entry.get("color", [1.0, 1.0, 1.0])
    if not (isinstance(color, list) and len(color) == 3 and all(finite_number(c) and 0.0 <= c <= 1.0 for c in color)):
        raise AssetError(f"{what}: color must be three numbers in [0, 1] (linear RGB), got {color!r}")
    intensity = entry.get("intensity", 1.0)
    if not (finite_number(intensity) and 0.0 <= intensity):
        raise AssetError(f"{what}: intensity must be a number >= 0, got {intensity!r}")
    reach = entry.get("range")
    if reach is not None and not (finite_number(reach) and reach > 0.0):
        raise AssetError(f"{what}: range must be a number > 0, got {reach!r}")
    inner, outer = 0.0, math.pi / 4.0
    if kind == "spot":
        spot = entry.get("spot")
        if not isinstance(spot, dict):
            raise AssetError(f"{what}: a spot light needs its spot object (innerConeAngle, outerConeAngle), "
                             f"got {spot!r}")
        inner, outer = spot.get("innerConeAngle", 0.0), spot.get("outerConeAngle", math.pi / 4.0)
        if not (finite_number(inner) and finite_number(outer) and 0.0 <= inner < outer <= math.pi / 2.0 + 1e-6):
            raise AssetError(f"{what}: its cone angles must satisfy 0 <= innerConeAngle < outerConeAngle <= pi/2 "
                             f"(radians), got {inner!r} and {outer!r}")
        if math.degrees(outer) < MIN_SPOT_ANGLE:
            raise AssetError(f"{what}: outerConeAngle {outer!r} is narrower than the engine's spot lights "
                             f"({MIN_SPOT_ANGLE} degrees, PointLight.spot_angle)")
        outer = min(outer, math.pi / 2.0)
    return ModelLight(kind, tuple(float(c) for c in color), float(intensity),
                      None if reach is None else float(reach), float(inner), float(outer), glm.mat4(),
                      name or f"light {index}", fields=_engine_fields(entry, kind, what))


def _engine_fields(entry: dict, kind: str, what: str) -> dict[str, object] | None:
    """The engine's fields from the light's ``extras`` (``LIGHT_EXTRAS``: ``LAMP_FIELDS`` for
    a point or spot, ``SUN_FIELDS`` for a directional light), their names and kinds of value
    checked here (their values by the light when it is made: ``spawn_model``); None where the
    file gives none."""
    extras = entry.get("extras")
    given = extras.get(LIGHT_EXTRAS) if isinstance(extras, dict) else None
    if given is None:
        return None
    allowed = SUN_FIELDS if kind == "directional" else LAMP_FIELDS
    light_class = "DirectionalLight" if kind == "directional" else "PointLight"
    if not isinstance(given, dict) or not set(given) <= set(allowed):
        raise AssetError(f"{what}: extras.{LIGHT_EXTRAS} must be an object of {light_class}'s fields "
                         f"{tuple(allowed)}, got {given!r}")
    fields: dict[str, object] = {}
    for name, value in given.items():
        want = allowed[name]
        if want == "bool":
            ok = isinstance(value, bool)
        elif want == "integer":
            ok = isinstance(value, int) and not isinstance(value, bool)
        elif want == "text":
            ok = isinstance(value, str)
        elif want == "pair":
            ok = isinstance(value, list) and len(value) == 2 and all(finite_number(side) for side in value)
            value = tuple(float(side) for side in value) if ok else value
        else:
            ok = finite_number(value)
            value = float(value) if ok else value
        if not ok:
            raise AssetError(f"{what}: extras.{LIGHT_EXTRAS}.{name} must be {_KINDS_SAID[want]} "
                             f"({light_class}.{name}), got {given[name]!r}")
        fields[name] = value
    return fields


def check_light_intensity(light: ModelLight, scale: float) -> float:
    """The engine light's intensity, ``scale`` x the file's; past the half floats the lit
    colour lands in it is an AssetError saying what brings it in range."""
    intensity = light.intensity * scale
    if intensity > HALF_MAX:
        unit = "lux" if light.kind == "directional" else "candela"
        raise AssetError(f"KHR_lights_punctual light {light.name!r}: intensity {light.intensity:g} {unit} x "
                         f"light_scale {scale:g} is past the engine's {HALF_MAX:g} (its lit colour is a half float): "
                         f"give spawn_model a light_scale of at most {HALF_MAX / max(light.intensity, 1e-30):.3g} and "
                         "raise the camera's exposure (Tonemap) by as many stops as that takes off")
    return intensity


def node_matrix(node: dict, index: int) -> np.ndarray:
    """A node's local transform: its ``matrix`` (column-major) or translation x rotation x scale."""
    if "matrix" in node:
        values = node["matrix"]
        if not (isinstance(values, list) and len(values) == 16 and all(finite_number(v) for v in values)):
            raise AssetError(f"node {index}: matrix must be 16 finite numbers, got {values!r}")
        return np.array(values, np.float64).reshape(4, 4).T
    t = node.get("translation", [0.0, 0.0, 0.0])
    r = node.get("rotation", [0.0, 0.0, 0.0, 1.0])
    s = node.get("scale", [1.0, 1.0, 1.0])
    for key, value, size in (("translation", t, 3), ("rotation", r, 4), ("scale", s, 3)):
        if not (isinstance(value, list) and len(value) == size and all(finite_number(v) for v in value)):
            raise AssetError(f"node {index}: {key} must be {size} finite numbers, got {value!r}")
    x, y, z, w = r
    if x * x + y * y + z * z + w * w == 0.0:
        raise AssetError(f"node {index}: rotation is not a unit quaternion, got {r!r}")
    rotation = np.array(glm.mat3_cast(glm.normalize(glm.dquat(w, x, y, z))).to_list(), np.float64).T
    matrix = np.eye(4)
    matrix[:3, :3] = rotation * np.asarray(s, np.float64)
    matrix[:3, 3] = t
    return matrix


def placed_nodes(doc: dict, nodes: list) -> list[tuple[int, np.ndarray]]:
    """Every node of the document's scene with its transform in the model (its ancestors'
    times its own), parents before children; a node reached twice (a cycle, or a child of
    two parents, which glTF forbids) is an AssetError."""
    scenes = doc.get("scenes") if isinstance(doc.get("scenes"), list) else []
    chosen = doc.get("scene", 0)
    if scenes and isinstance(chosen, int) and not isinstance(chosen, bool) and 0 <= chosen < len(scenes) \
            and isinstance(scenes[chosen], dict):
        roots = scenes[chosen].get("nodes") or []
    else:  # no scene: the nodes no node names as a child
        children = {c for node in nodes if isinstance(node, dict) for c in (node.get("children") or [])}
        roots = [i for i in range(len(nodes)) if i not in children]
    placed: list[tuple[int, np.ndarray]] = []
    seen: set[int] = set()
    stack = [(index, np.eye(4)) for index in reversed(list(roots))]
    while stack:
        index, parent = stack.pop()
        if isinstance(index, bool) or not isinstance(index, int) or not 0 <= index < len(nodes) \
                or not isinstance(nodes[index], dict):
            raise AssetError(f"the node tree names node {index!r}, which the file does not have")
        if index in seen:
            raise AssetError(f"node {index} is reached twice in the node tree (glTF's nodes form a tree)")
        seen.add(index)
        matrix = parent @ node_matrix(nodes[index], index)
        if not np.isfinite(matrix).all():
            raise AssetError(f"node {index}: its transform in the model is not finite")
        placed.append((index, matrix))
        stack.extend((child, matrix) for child in reversed(list(nodes[index].get("children") or [])))
    return placed
