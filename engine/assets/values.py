"""How component field values are written as plain JSON: one encoder shared by level files
(``engine.assets.level_file.save_level``) and scene export (``shell.capture``), so a value
saved one way reads back the other."""
from __future__ import annotations

import dataclasses
import json
import math
from typing import Any

import numpy as np
from pyglm import glm

from engine.assets.mesh import Mesh
from engine.assets.texture_data import TextureData

# How component field values are written to scene.json (``component_values``).  Every kind
# is plain JSON; ``VALUE_KINDS`` goes into the file so a tool reading it needs nothing else.
VALUE_KINDS = {
    "null": "no value (None)",
    "bool": "true / false",
    "int": "an integer (Transform.parent, Portal.partner, PortalClone.source/.portal: an entity id)",
    "float": "a number; inf, -inf and nan are written as those strings",
    "str": "a string",
    "vec2": "[x, y]", "vec3": "[x, y, z]", "vec4": "[x, y, z, w] (colours: [r, g, b, a])",
    "quat": "[w, x, y, z]: a unit quaternion, w first (glm.quat(w, x, y, z))",
    "mat4": "16 numbers, column by column (glm's order)",
    "list": "a list of values, each written by these rules",
    "array": "{'shape': [...], 'dtype': ..., 'values': nested lists} (a numpy array of up to 64 values)",
    "array_summary": "{'shape': [...], 'dtype': ...} (a larger numpy array, e.g. generated sky faces)",
    "mesh": "{'name', 'id', 'vertices', 'triangles', 'bounds': [min xyz, max xyz] local}: entities with "
            "the same id share one mesh; the entity's geometry is node <entity id> of the .glb/.gltf beside "
            "this file, in world space (its Transform's world matrix undoes it)",
    "texture": "{'name', 'size': [width, height]}: pixels by name, not embedded",
    "object": "an object's public fields, each written by these rules",
}
_GLM_KIND = {glm.vec2: "vec2", glm.vec3: "vec3", glm.vec4: "vec4", glm.quat: "quat", glm.mat4: "mat4"}
_ARRAY_VALUES_MAX = 64


def json_value(value: Any) -> tuple[Any, str]:
    """``value`` as plain JSON and the kind it was written as (a key of ``VALUE_KINDS``)."""
    if value is None:
        return None, "null"
    if isinstance(value, bool | np.bool_):
        return bool(value), "bool"
    if isinstance(value, int | np.integer):
        return int(value), "int"
    if isinstance(value, float | np.floating):
        return _number(value), "float"
    if isinstance(value, str):
        return value, "str"
    kind = _GLM_KIND.get(type(value))
    if kind == "quat":
        return [_number(v) for v in (value.w, value.x, value.y, value.z)], kind
    if kind == "mat4":
        return [_number(v) for column in value.to_list() for v in column], kind
    if kind is not None:
        return [_number(v) for v in value], kind
    if isinstance(value, Mesh):
        low, high = value.positions.min(axis=0), value.positions.max(axis=0)
        return {"name": value.name, "id": value.id, "vertices": len(value.positions),
                "triangles": len(value.indices), "bounds": [[_number(v) for v in low], [_number(v) for v in high]]}, \
            "mesh"
    if isinstance(value, TextureData):
        height, width = np.asarray(value.pixels).shape[:2]
        return {"name": value.name, "size": [int(width), int(height)]}, "texture"
    if isinstance(value, np.ndarray):
        summary = {"shape": list(value.shape), "dtype": str(value.dtype)}
        if value.size > _ARRAY_VALUES_MAX:
            return summary, "array_summary"
        return {**summary, "values": json.loads(json.dumps(value.tolist(), default=str))}, "array"
    if isinstance(value, list | tuple):
        return [json_value(v)[0] for v in value], "list"
    return {name: json_value(v)[0] for name, v in public_fields(value).items()}, "object"


def _number(value: Any) -> float | str:
    value = float(value)
    return value if math.isfinite(value) else str(value)


def public_fields(component: Any) -> dict[str, Any]:
    """The fields a component is made from: a dataclass's init fields, else its public attributes."""
    if dataclasses.is_dataclass(component):
        return {f.name: getattr(component, f.name) for f in dataclasses.fields(component)
                if f.init and not f.name.startswith("_")}
    return {name: v for name, v in vars(component).items() if not name.startswith("_")}
