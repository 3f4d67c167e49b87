"""Material variants (glTF's ``KHR_materials_variants``): one model in several looks (a shoe
in three colourways, a car's paints, a chair's fabrics), each primitive naming the material
it wears in each variant, as three.js's, Babylon.js's and Filament's viewers switch them.

``apply_variant`` rewrites each primitive's ``material`` to the chosen variant's before
trimesh parses the file (as ``gltf_instancing`` and ``gltf_accessors`` prepare it), so
the parts are read with the variant's materials by the same code as any file's; a primitive
the variant does not map keeps its default material.  ``Model.variant`` (and
``spawn_model(variant=...)``) choose one; "" is the file's default look.
"""
from __future__ import annotations

from engine.core.errors import AssetError

EXTENSION = "KHR_materials_variants"


def variant_names(doc: dict | None) -> list[str]:
    """The names of a glTF document's variants, in the file's order ([] without any); a
    malformed list is an AssetError."""
    extensions = doc.get("extensions") if isinstance(doc, dict) else None
    info = extensions.get(EXTENSION) if isinstance(extensions, dict) else None
    if info is None:
        return []
    variants = info.get("variants") if isinstance(info, dict) else None
    if not isinstance(variants, list) or not all(
            isinstance(v, dict) and isinstance(v.get("name"), str) and v["name"] for v in variants):
        raise AssetError(f"{EXTENSION}.variants must be a list of objects each with a name, got {variants!r}")
    return [v["name"] for v in variants]


def apply_variant(doc: dict, variant: str | None) -> None:
    """Give each primitive the material ``variant`` maps it to (None or "": the default look).
    A variant the file does not have (the error lists those it has), or a mapping naming a
    variant or material the file does not have, is an AssetError."""
    names = variant_names(doc)
    if not variant:
        return
    if variant not in names:
        having = f"its variants: {', '.join(repr(n) for n in names)}" if names else "it has none"
        raise AssetError(f"has no material variant {variant!r} ({having}; {EXTENSION})")
    chosen = names.index(variant)
    materials = doc.get("materials") if isinstance(doc.get("materials"), list) else []
    for m, mesh in enumerate(doc.get("meshes") or []):
        for p, primitive in enumerate((mesh.get("primitives") or []) if isinstance(mesh, dict) else []):
            extensions = primitive.get("extensions") if isinstance(primitive, dict) else None
            info = extensions.get(EXTENSION) if isinstance(extensions, dict) else None
            if info is None:
                continue
            mappings = info.get("mappings") if isinstance(info, dict) else None
            if not isinstance(mappings, list):
                raise AssetError(f"mesh {m} primitive {p}: {EXTENSION}.mappings must be a list, got {mappings!r}")
            for mapping in mappings:
                material = mapping.get("material") if isinstance(mapping, dict) else None
                variants = mapping.get("variants") if isinstance(mapping, dict) else None
                if not isinstance(variants, list) or not all(
                        isinstance(v, int) and not isinstance(v, bool) and 0 <= v < len(names) for v in variants):
                    raise AssetError(f"mesh {m} primitive {p}: a {EXTENSION} mapping's variants must be indices of "
                                     f"the file's {len(names)} variants, got {variants!r}")
                if isinstance(material, bool) or not isinstance(material, int) or not 0 <= material < len(materials):
                    raise AssetError(f"mesh {m} primitive {p}: a {EXTENSION} mapping names material {material!r}, "
                                     "which the file does not have")
                if chosen in variants:
                    primitive["material"] = material
