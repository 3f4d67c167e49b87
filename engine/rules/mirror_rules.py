"""What makes a mesh a mirror: one rule, ``mirror_mesh``, registered with every world as an
invariant (``engine.core.world.world_invariant``), so a bad mirror is refused when it is
made, not on the next frame inside the surfaces stage.

A mirror needs a mesh with area (its plane comes from it, unless ``Mirror.plane_normal``
gives one) that is flat; a mirror with a normal map needs UVs that vary linearly over its
plane (``engine.assets.mesh.planar_uv_map``).  Checked when a Mirror, MeshRef or Material
joins an entity holding the others, when a mirror's ``MeshRef.mesh`` is replaced and when
its ``Material.normal_map`` is set.  The surfaces stage (``systems/surface_system.py``)
takes the mirror's plane and UV map from the same function, so what the world accepted is
what is drawn, and a mesh changed behind the world's back is refused there with the same
reason.

A mirror or portal is drawn whole and from its front: its claim of its pixels has no holes,
so a cutout material (``Material.alpha_cutoff``) or a double-sided one
(``Material.double_sided``) is refused on one (``check_surface_material``).  A portal's
mesh not flat in its rectangle's plane is said, not refused (``warn_portal_not_flat``).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from components import (
    ComponentValueError,
    Emissive,
    Material,
    MeshRef,
    Mirror,
    Portal,
    Reflective,
    Refractive,
    Transform,
)
from components.tracking import warn_component
from engine.assets.mesh import Mesh, flat_plane, planar_uv_map
from engine.core.world import World, world_invariant


class MirrorMeshError(ValueError):
    """Why a mesh cannot make a mirror: the reason alone; the caller names the entity."""


@dataclass(frozen=True)
class MirrorMesh:
    """What a mirror makes of its mesh, in model space."""

    point: np.ndarray  # a point on the mirror's plane
    normal: np.ndarray  # the plane's normal (the side the mirror reflects)
    uv_rows: np.ndarray | None  # with a normal map: (2, 4) rows, the UVs as an affine map of position


def mirror_mesh(mirror: Mirror, mesh: Mesh, normal_map: bool = False, second_uvs: bool = False) -> MirrorMesh:
    """The mirror rule: the plane of ``mirror`` on ``mesh`` (``Mirror.plane_normal`` through
    ``plane_point`` when given, else the flat mesh's own) and, with a normal map, the mesh's
    planar UV map (of its second UV set with ``second_uvs``: the map reads it,
    ``Material.second_uv_maps``); ``MirrorMeshError`` says why there is none."""
    uv_rows = None
    if normal_map:
        uv_rows, why = planar_uv_map(mesh, second_uvs)
        if uv_rows is None:
            raise MirrorMeshError(f"Material.normal_map needs UVs that vary linearly over the mirror (mesh "
                                  f"{mesh.name!r}: {why}); use a flat mesh with planar UVs, such as a quad")
    if mirror.plane_normal is not None:
        point = np.array(mirror.plane_point if mirror.plane_point is not None else (0.0, 0.0, 0.0))
        return MirrorMesh(point, np.array(mirror.plane_normal), uv_rows)
    tri = mesh.positions[mesh.indices]
    area = float(np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1).sum())
    if not area > 0.0:
        raise MirrorMeshError(f"its MeshRef.mesh {mesh.name!r} has no area (a mirror needs a flat mesh of non-zero "
                              f"size), got area {area}")
    found = flat_plane(mesh)
    if found is None:
        lo, hi = mesh.bounds
        raise MirrorMeshError(f"its MeshRef.mesh {mesh.name!r} is not flat (model-space extents "
                              f"{[round(float(v), 3) for v in hi - lo]}); give the mirror a flat mesh or plane_normal")
    return MirrorMesh(found[0], found[1], uv_rows)


@world_invariant(Mirror, MeshRef, Material)
def check_mirror_mesh(world: World, entity: int, joining: Any = None, mesh: Mesh | None = None,
                      normal_map: Any = None, second_uv_maps: Any = None, **_other: Any) -> None:
    """Refuse ``entity`` as a mirror when its mesh (``mesh``: a replacement about to be set)
    or, with a normal map (``normal_map``: one about to be set), the UVs it reads
    (``second_uv_maps``: a choice about to be set) cannot make one (``_other``: values about
    to be set that other rules check)."""
    exists = world.exists(entity)
    if type(joining) is not Mirror and (not exists or world.try_get(entity, Mirror) is None):
        return  # (most entities: no mirror, nothing more to look up)
    held = {kind: world.try_get(entity, kind) if exists else None for kind in (Mirror, MeshRef, Material)}
    if joining is not None:
        held[type(joining)] = joining
    mirror, mesh_ref, material = held[Mirror], held[MeshRef], held[Material]
    if mesh is None and mesh_ref is not None:
        mesh = mesh_ref.mesh
    if mirror is None or mesh is None:
        return
    second = second_uv_maps if second_uv_maps is not None else getattr(material, "second_uv_maps", ())
    if "normal_map" in second and mesh.second_uvs is None:
        return  # (the second-UV rule refuses it: engine/rules/uv_rules.py)
    try:
        mirror_mesh(mirror, mesh, (normal_map or getattr(material, "normal_map", None)) is not None,
                    "normal_map" in second)
    except MirrorMeshError as exc:
        raise ComponentValueError(f"Mirror on entity {entity}: {exc}") from None


@world_invariant(Portal, Transform)
def check_portal_not_mirrored(world: World, entity: int, joining: Any = None, scale: Any = None,
                              **_other: Any) -> None:
    """Refuse a portal whose own Transform mirrors it (``scale``: one about to be set; an odd
    number of negative parts): what a pair carries is a turn and a move, so its view and what
    goes through it cannot be a mirror image (the usual mistake: a scale of -1 to face a portal
    the other way, which a half turn does)."""
    exists = world.exists(entity)
    if type(joining) is not Portal and (not exists or world.try_get(entity, Portal) is None):
        return  # (most entities: no portal, nothing more to look up)
    if scale is None:
        transform = joining if type(joining) is Transform else world.try_get(entity, Transform) if exists else None
        scale = transform.scale if transform is not None else None
    if scale is None:
        return
    if sum(1 for part in scale if part < 0.0) % 2:
        raise ComponentValueError(
            f"Portal on entity {entity}: Transform.scale {tuple(float(v) for v in scale)} mirrors it (an odd number "
            "of negative parts), and a portal's view and what goes through it cannot be mirror images; turn it "
            "to face the other way (a half turn about its up axis), or make it a Mirror")


# A portal's mesh deeper than this share of its widest side along its local Z is not flat in
# the XY plane its rectangle lies in (``warn_portal_not_flat``).
PORTAL_FLAT_SHARE = 1e-3
# A portal's flat mesh whose outline's edges lie further than this share of its rectangle's
# larger side from Portal.size's rectangle's is not that rectangle (``warn_portal_not_flat``).
PORTAL_OUTLINE_SHARE = 0.01


@world_invariant(Portal, MeshRef)
def warn_portal_not_flat(world: World, entity: int, joining: Any = None, mesh: Mesh | None = None,
                         size: Any = None, **_other: Any) -> None:
    """Say (a ComponentWarning, when a Portal or a MeshRef joins, the mesh is replaced or the
    portal's ``size`` set) a portal whose mesh is not flat in its local XY plane, where its
    rectangle lies: every pixel of the mesh shows the view through the portal (a box's sides
    and back too), while things go through the rectangle alone.  Allowed (a frame with depth
    drawn as the opening is a choice), but a unit box (the editor's first mesh) is usually a
    mesh not yet made a quad.  And a flat mesh whose outline is not ``Portal.size``'s
    rectangle (centred on the entity: ``engine.assets.mesh.quad``'s): the view shows on the
    mesh's pixels and things go through (and are cut at) the rectangle, so where only one of
    them reaches, something walks into a wall the view shows open, or through a doorway it
    shows shut: a quad of one size with a Portal of the default size (2, 3) is the usual way."""
    exists = world.exists(entity)
    portal = joining if type(joining) is Portal else world.try_get(entity, Portal) if exists else None
    if portal is None:
        return  # (most entities: no portal, nothing more to look up)
    if mesh is None:
        mesh_ref = joining if type(joining) is MeshRef else world.try_get(entity, MeshRef) if exists else None
        mesh = mesh_ref.mesh if mesh_ref is not None else None
    if mesh is None:
        return
    lo, hi = mesh.bounds
    depth, widest = float(hi[2] - lo[2]), float(max(hi[0] - lo[0], hi[1] - lo[1]))
    if depth > PORTAL_FLAT_SHARE * max(widest, 1e-9):
        warn_component(f"Portal on entity {entity}: its MeshRef.mesh {mesh.name!r} is not flat in its local XY "
                       f"plane (z from {float(lo[2]):.3g} to {float(hi[2]):.3g}), where the portal's rectangle lies: "
                       "every pixel of it shows the view through the portal, its sides and back too; give it a "
                       "quad (engine.assets.mesh.quad(width, height), the size of Portal.size)")
        return
    w, h = size if size is not None else portal.size
    edges = (float(lo[0]) + w / 2, float(hi[0]) - w / 2, float(lo[1]) + h / 2, float(hi[1]) - h / 2)
    if max(abs(e) for e in edges) > PORTAL_OUTLINE_SHARE * max(w, h):
        warn_component(f"Portal on entity {entity}: its MeshRef.mesh {mesh.name!r} spans x {float(lo[0]):.3g} to "
                       f"{float(hi[0]):.3g}, y {float(lo[1]):.3g} to {float(hi[1]):.3g}, but Portal.size "
                       f"{(float(w), float(h))} is the rectangle x {-w / 2:.3g} to {w / 2:.3g}, y {-h / 2:.3g} to "
                       f"{h / 2:.3g}: the view shows on the mesh and things go through the rectangle, so where one "
                       "reaches and the other not, a thing walks through a wall the view shows shut or into one it "
                       "shows open; give the Portal the quad's size (or the quad the Portal's)")


@world_invariant(Mirror, Portal, Material)
def check_surface_material(world: World, entity: int, joining: Any = None, alpha_cutoff: Any = None,
                           double_sided: Any = None, **_other: Any) -> None:
    """Refuse a cutout material (``alpha_cutoff``: one about to be set) on a mirror or a
    portal: its claim pass and its composite draw the whole surface, so a hole would show
    the reflection, not what is behind; and a double-sided one (``double_sided``): a
    surface is seen from its front, its view drawn only there."""
    held = {kind: world.try_get(entity, kind) if world.exists(entity) else None for kind in (Mirror, Portal, Material)}
    if joining is not None:
        held[type(joining)] = joining
    material = held[Material]
    cutoff = alpha_cutoff if alpha_cutoff is not None else getattr(material, "alpha_cutoff", None)
    surface = "Mirror" if held[Mirror] is not None else "Portal" if held[Portal] is not None else None
    if cutoff is not None and surface is not None:
        raise ComponentValueError(f"entity {entity}: Material.alpha_cutoff {cutoff} on a {surface}: a mirror or "
                                  "portal is drawn whole (its claim of its pixels has no holes); put the cutout "
                                  "on an entity in front of it")
    sides = double_sided if double_sided is not None else getattr(material, "double_sided", False)
    if sides and surface is not None:
        raise ComponentValueError(f"entity {entity}: Material.double_sided on a {surface}: a mirror or portal is "
                                  "seen from its front only (give its back an entity of its own)")


@world_invariant(Mirror, Portal)
def check_one_surface(world: World, entity: int, joining: Any = None, **_other: Any) -> None:
    """Refuse a Mirror and a Portal on one entity: each makes the surface's pixels show a view
    of its own (a mirror's reflection, a portal's partner's side), so a surface is one or the
    other."""
    if not isinstance(joining, (Mirror, Portal)) or not world.exists(entity):
        return
    other = Portal if isinstance(joining, Mirror) else Mirror
    if world.try_get(entity, other) is not None:
        raise ComponentValueError(f"entity {entity}: a {type(joining).__name__} on an entity with a {other.__name__}: "
                                  "its pixels show one view, a mirror's reflection or a portal's partner's side; "
                                  "make the other an entity of its own")


# An object's own looks, which a mirror's or portal's pixels cannot also have: the view they
# show leaves a Reflective's reflection and an Emissive's glow out (nothing changed), and a
# Refractive draws the material's colour in place of the view (the view gone).
_OBJECT_LOOKS = (Reflective, Refractive, Emissive)


@world_invariant(Mirror, Portal, *_OBJECT_LOOKS)
def check_surface_looks(world: World, entity: int, joining: Any = None, **_other: Any) -> None:
    """Refuse a Reflective, Refractive or Emissive on an entity with a Mirror or Portal (either
    joining the other): its pixels show a view (a mirror's reflection, a portal's partner's
    side), which the object look would leave unchanged or hide."""
    if not isinstance(joining, (Mirror, Portal, *_OBJECT_LOOKS)) or not world.exists(entity):
        return
    if isinstance(joining, (Mirror, Portal)):
        surface, looks = joining, [kind for kind in _OBJECT_LOOKS if world.try_get(entity, kind) is not None]
    else:
        surface, looks = world.try_get(entity, Mirror) or world.try_get(entity, Portal), [type(joining)]
    if surface is None or not looks:
        return
    kind, look = type(surface).__name__, looks[0].__name__
    view = "its reflection" if isinstance(surface, Mirror) else "its partner's side"
    effect = f"would hide {view} (the material's colour drawn in its place)" if looks[0] is Refractive else \
        f"changes nothing (its pixels show {view}, not a look of their own)"
    own_look = "; or set a mirror's own look with Mirror.color and reflect_rate" if isinstance(surface, Mirror) else ""
    article = "an" if look[0] in "AEIOU" else "a"
    raise ComponentValueError(f"entity {entity}: {article} {look} on a {kind} {effect}: give the {look} an entity "
                              f"of its own (a glowing frame, a pane of glass in front){own_look}")
