"""Instance records of one (mesh, texture) pair, kept in a numpy array and uploaded by rows.

One batch is one instanced draw, so draw calls grow with distinct meshes, not entities.
Rows are packed (a removed entity's row is filled with the last row), and only rows
written since the last upload are sent again: a frame where nothing changed uploads
nothing.
"""
from __future__ import annotations

import math
import re
import weakref
from typing import NamedTuple

import moderngl
import numpy as np
from pyglm import glm

from components.limits import NO_RECEIVE_BIT
from engine.assets.mesh import Mesh
from engine.render.object_motion import ObjectMotion
from engine.rules.visibility_rules import row_casts_shadow

INSTANCE_DTYPE = np.dtype([
    ("model", "<f4", (16,)),          # column-major mat4
    ("normal_matrix", "<f4", (9,)),   # column-major mat3
    ("color", "<f4", (4,)),
    ("surface", "<f4", (4,)),         # metallic, roughness, emissive power, normal-map scale
    ("reflect", "<f4", (4,)),         # reflection mix, refraction ior, weights of the batch's probe and second probe
    ("tint", "<f4", (4,)),            # reflection tint rgb; w: where it is drawn (entity_code)
    ("slice", "<f4", (4,)),           # world plane; only its front is drawn ((0,0,0,1): all)
    ("slots", "<u4", (4,)),           # emissive, refract, reflect variants, entity id
])
# Components of the vec4 fields above that carry a meaning of their own (the scene shaders
# read them by these positions: in_reflect.y the index, in_reflect.zw the weights, in_tint.w).
REFLECT_MIX, REFRACTION_IOR, PROBE_WEIGHTS = 0, 1, slice(2, 4)  # "reflect": mix, ior, each probe's weight
TINT_VISIBILITY = 3                                             # "tint": visibility_code
INSTANCE_FORMAT = "16f 9f 4f 4f 4f 4f 4f 4u/i"
_MATRIX_FLOATS = 25  # "model" then "normal_matrix": a row's first floats (InstanceBatch._matrices)
assert INSTANCE_DTYPE.fields["model"][1] == 0 and INSTANCE_DTYPE.fields["normal_matrix"][1] == 64
INSTANCE_ATTRIBUTES = ("in_model", "in_normal_matrix", "in_color", "in_surface", "in_reflect", "in_tint",
                       "in_slice", "in_slots")


def _instance_columns() -> tuple[tuple[str, int, str, str, int], ...]:
    """Each instance input's vertex attributes: (input, column, moderngl's class, format,
    byte offset in a row); a matrix takes one location a column (in_model four, in_normal_matrix
    three), the entity's uvec4 an integer one."""
    columns = []
    for name, field in zip(INSTANCE_ATTRIBUTES, INSTANCE_DTYPE.names, strict=True):
        dtype, offset = INSTANCE_DTYPE.fields[field][:2]
        count = dtype.shape[0]
        side = {16: 4, 9: 3}.get(count)
        if side is not None:
            columns += [(name, column, "f", f"{side}f", offset + 4 * side * column) for column in range(side)]
        else:
            integer = dtype.base.kind == "u"
            columns.append((name, 0, "i" if integer else "f", f"{count}{'u' if integer else 'f'}", offset))
    return tuple(columns)


_INSTANCE_COLUMNS = _instance_columns()


# An instance's ``tint`` w is where it is drawn: ``engine.rules.visibility_rules.entity_code``,
# the kinds of view it is hidden in and the reflection layers it belongs to.  Every vertex
# attribute GL 4.1 guarantees is in use, so it rides in a float slot the scene shaders do not
# read otherwise: an integer below 2^20 is exact in a float32 (24-bit significand), and
# ``shaders/include/visibility.glsl`` reads it back as a uint.
VERTEX_ATTRIBUTES = ("in_position", "in_normal", "in_uv")

# Many separate dirty runs are sent as one span when the span is not much bigger than the
# rows themselves (one write call beats many); otherwise run by run, so scattered movers
# in a big batch do not resend everything between them.
_SPAN_SLACK = 4
# Movers of one batch in a frame from which their rows are gathered at the batch's front
# (InstanceBatch.write_transforms).
_GATHER_AT = 16


# Texels a row of a mesh's morph-offset texture (GpuMesh.morphs; GL 4.1 promises 16384).
MORPH_TEXTURE_WIDTH = 1024


# Rows an upload measures (world boxes, largest scale) in Python floats rather than arrays
# (InstanceBatch._measure_few): below it the arrays' fixed cost a call is most of the work.
_FEW_ROWS = 8
# The changed boxes kept apart for the shadow maps (InstanceBatch.take_changes): a frame's few
# movers; past this, their union alone.
MAX_CHANGED_PARTS = 16


# Rows from which write_transforms works the normal matrices out on arrays (normal_matrices)
# rather than one glm call chain a row: a dozen numpy calls cost about what 30 rows' glm do.
_NORMALS_ON_ARRAYS = 32


def _union_holds(union: tuple[list[float], list[float]], old_lo: list[float], old_hi: list[float],
                 new_lo: list[float], new_hi: list[float]) -> bool:
    """Whether the union of a batch's row boxes is the same numbers after one row's box went
    from [old_lo, old_hi] (NaN: the row was never measured) to [new_lo, new_hi]: face by face,
    a row whose face did not move changes nothing; one that moved keeps the union's face if
    it was not on it (strictly inside: another row holds the face) and is not past it now.
    Exact: the union is the least and the greatest of the same floats."""
    low, high = union
    for i in range(3):
        old, new = old_lo[i], new_lo[i]
        if old != new and (new < low[i] or not old > low[i]):  # NaN: old > low is False
            if old == old or new < low[i]:
                return False
        old, new = old_hi[i], new_hi[i]
        if old != new and (new > high[i] or not old < high[i]):
            if old == old or new > high[i]:
                return False
    return True


def _inverse_terms() -> tuple[np.ndarray, ...]:
    """Index tables for ``normal_matrices``: for each element of the normal matrix (column-major
    3x3, element (c, r) = inverse (r, c)), the four model elements (indices into the flat
    column-major 4x4) of its cofactor ``a * b - c * d``, and its sign, in the order and form
    GLM's ``inverse(mat3)`` writes them (``Inverse[i][j]`` below, column i, row j)."""
    glm_inverse = {  # Inverse[i][j]: sign, then m[.][.] of "a * b - c * d" (m[column][row])
        (0, 0): (1, (1, 1), (2, 2), (2, 1), (1, 2)), (1, 0): (-1, (1, 0), (2, 2), (2, 0), (1, 2)),
        (2, 0): (1, (1, 0), (2, 1), (2, 0), (1, 1)), (0, 1): (-1, (0, 1), (2, 2), (2, 1), (0, 2)),
        (1, 1): (1, (0, 0), (2, 2), (2, 0), (0, 2)), (2, 1): (-1, (0, 0), (2, 1), (2, 0), (0, 1)),
        (0, 2): (1, (0, 1), (1, 2), (1, 1), (0, 2)), (1, 2): (-1, (0, 0), (1, 2), (1, 0), (0, 2)),
        (2, 2): (1, (0, 0), (1, 1), (1, 0), (0, 1)),
    }
    terms = [glm_inverse[(r, c)] for c in range(3) for r in range(3)]  # normal (c, r) = Inverse[r][c]
    index = [np.array([t[k][0] * 4 + t[k][1] for t in terms]) for k in range(1, 5)]
    return (*index, np.array([t[0] for t in terms], np.float32))


_COFACTOR_A, _COFACTOR_B, _COFACTOR_C, _COFACTOR_D, _COFACTOR_SIGN = _inverse_terms()


def normal_matrices(models: np.ndarray) -> np.ndarray:
    """The normal matrices (n, 9), column-major, of float32 model matrices (n, 16): the inverse
    transpose of each upper 3x3 by cofactors over determinant, all rows at once, with GLM's
    ``transpose(inverse(mat3(m)))`` arithmetic in float32 step for step (the same operands,
    order and rounding), so a row is the same bits whichever path wrote it."""
    u = models[:, _COFACTOR_A] * models[:, _COFACTOR_B] - models[:, _COFACTOR_C] * models[:, _COFACTOR_D]
    # GLM's determinant: + m00 (m11 m22 - m21 m12) - m10 (m01 m22 - m21 m02) + m20 (m01 m12 - m11 m02),
    # those cofactors being the normal matrix's elements 0, 3 and 6 before their signs.
    det = models[:, 0] * u[:, 0] - models[:, 4] * u[:, 3] + models[:, 8] * u[:, 6]
    with np.errstate(divide="ignore"):
        one = np.float32(1.0) / det
    u *= one[:, None]
    u *= _COFACTOR_SIGN  # a sign flip is exact: (-x) * one == -(x * one)
    return u


_FORMAT_PART = re.compile(r"^(\d*)([fiu])(\d?)$")


# What each program reads of each layout (``read_by``), kept while the program lives: every
# new batch makes a vertex array for each build a view may draw it with, a dozen or so, each
# reading three buffers' layouts the same way as the last batch's did.
_READS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def read_by(program: moderngl.Program, buffer: moderngl.Buffer, layout: str, *names: str) -> tuple | None:
    """A vertex array's entry for ``buffer`` (``layout``: moderngl's format, one part a name)
    as ``program`` reads it: the inputs the build does not read (its linker dropped them)
    skipped as padding bytes; None where it reads none.  Rather than moderngl's
    ``skip_errors``, which gives a name the program lacks the location of a built-in input
    the program reads (gl_VertexID's -1: the MORPHED builds'), so GL refuses the array
    (GL_INVALID_VALUE)."""
    reads = _READS.get(program)
    if reads is None or reads.get(_GLO) != program.glo:  # (a program relinked under the same object)
        reads = _READS[program] = {_GLO: program.glo}
    key = (layout, names)
    found = reads.get(key, _UNREAD)
    if found is _UNREAD:
        found = reads[key] = _read_by(program, layout, names)
    return None if found is None else (buffer, *found)


_UNREAD = object()
_GLO = object()  # a program's entry's key for the GL program name it was read from


def forget_reads() -> None:
    """Forget what every program reads (``read_by``): after a shader hot reload relinks them."""
    _READS.clear()


def _read_by(program: moderngl.Program, layout: str, names: tuple[str, ...]) -> tuple | None:
    """``read_by``'s answer less the buffer: (layout, the names read...), or None."""
    parts = layout.split()
    per_instance = parts[-1].endswith("/i")
    if per_instance:
        parts[-1] = parts[-1][:-2]
    kept, layout_parts = [], []
    for part, name in zip(parts, names, strict=True):
        if name in program:
            kept.append(name)
            layout_parts.append(part)
            continue
        count, kind, size = _FORMAT_PART.match(part).groups()
        layout_parts.append(f"{int(count or 1) * int(size or 4)}x")
    if not kept:
        return None
    return (" ".join(layout_parts) + ("/i" if per_instance else ""), *kept)


class GpuMesh:
    """Vertex and index buffers of one Mesh, shared by every batch that draws it."""

    def __init__(self, ctx: moderngl.Context, mesh: Mesh) -> None:
        self.vertices = ctx.buffer(mesh.interleaved().tobytes())
        # Its layout (Mesh.vertex_format): a second UV set (Mesh.second_uvs) makes ``in_uv`` four
        # floats; without one the shaders' vec4 reads (u, v, 0, 1).
        self.vertex_format = mesh.vertex_format
        self.indices = ctx.buffer(mesh.indices.astype(np.uint32).tobytes())
        # Its colour a vertex (Mesh.colors, linear RGBA), a buffer of its own (None: none): the
        # VERTEX_COLOR builds read it (and a cutout's VERTEX_ALPHA shadow build its alpha).
        self.colors = ctx.buffer(mesh.rgba_colors().tobytes()) if mesh.colors is not None else None
        # A skinned mesh's joints and weights a vertex (Mesh.joints, Mesh.weights; None: not
        # skinned): the SKINNED builds read them (shaders/include/pose.glsl).
        self.skin = ctx.buffer(mesh.skin_interleaved()) if mesh.skinned else None
        # A mesh with morph targets: their offsets a vertex in a float texture (Mesh.morph_texels,
        # MORPH_TEXTURE_WIDTH texels a row), which the MORPHED builds read by gl_VertexID.
        self.morph_count = mesh.morph_count
        self.morphs = self._morph_texture(ctx, mesh) if mesh.morph_count else None
        self.has_alpha = mesh.has_alpha  # some vertex's alpha below 1 (Mesh.has_alpha)
        self.index_count = mesh.indices.size
        # Model-space radius about the origin (what an instance's scale stretches).
        self.radius = float(np.linalg.norm(mesh.positions, axis=1).max()) if len(mesh.positions) else 0.0
        # The corners of its model-space box, homogeneous (what an instance's world box is made from).
        lo = mesh.positions.min(axis=0) if len(mesh.positions) else np.zeros(3)
        hi = mesh.positions.max(axis=0) if len(mesh.positions) else np.zeros(3)
        self.corners = np.array([[x, y, z, 1.0] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                                 for z in (lo[2], hi[2])], np.float64)
        # The same box as (lo/hi, column, 1), to scale a model matrix's axes by (InstanceBatch._grow_box).
        self.box_ends = np.array([lo, hi], np.float64).reshape(2, 3, 1)
        self.box_lo, self.box_hi = tuple(float(v) for v in lo), tuple(float(v) for v in hi)  # the same, as floats

    @staticmethod
    def _morph_texture(ctx: moderngl.Context, mesh: Mesh) -> moderngl.Texture:
        texels = mesh.morph_texels()
        rows = -(-len(texels) // MORPH_TEXTURE_WIDTH)
        filled = np.zeros((rows * MORPH_TEXTURE_WIDTH, 4), np.float32)  # every texel written (a GPU zeroes nothing)
        filled[: len(texels)] = texels
        texture = ctx.texture((MORPH_TEXTURE_WIDTH, rows), 4, filled.tobytes(), dtype="f4")
        texture.filter = (moderngl.NEAREST, moderngl.NEAREST)
        return texture

    def release(self) -> None:
        self.vertices.release()
        self.indices.release()
        for obj in (self.colors, self.skin, self.morphs):
            if obj is not None:
                obj.release()


class BatchKey(NamedTuple):
    """What sorts an instance into its batch (``Renderer.batch_for``): instances that share
    all of it are drawn together, with one program build and one set of textures.  Image
    fields are the images' ``id`` (0: none)."""

    mesh: int                       # Mesh.id
    texture: int                    # the albedo texture
    probes: tuple[int, int, bool, int]  # (probe, second probe, probe blend, rest probe): the probes it samples
    transparent_entity: int         # a transparent entity's own batch (0: opaque, shared)
    normal_map: int
    emissive_map: int
    metallic_roughness_map: int
    mirrored: bool                  # a negative determinant: the other winding
    alpha_cutoff: float | None = None  # a cutout's (Material.alpha_cutoff): its draws' uniform
    occlusion_map: int = 0              # its image's id (0: none)
    occlusion_strength: float = 1.0     # Material.occlusion_strength: its draws' uniform
    double_sided: bool = False          # Material.double_sided: drawn with face culling off
    keeps_specular: bool = False        # a transparent one's Material.blend "transparent"
    clearcoat: tuple[float, float] | None = None  # Material.clearcoat and its roughness (None: none)
    unlit: bool = False                 # Material.unlit: its colour as it is (the UNLIT_MATERIAL build)
    dielectric_f0: tuple[float, float, float] = (0.04, 0.04, 0.04)  # its non-metal's f0 (RGB): its draws' uniform
    sheen: tuple[float, float, float, float] | None = None  # Material.sheen_color and roughness (None: none)
    dispersion: float = 0.0             # Refractive.dispersion: its DISPERSION build's uniform (0: none)
    anisotropy: tuple[float, float] | None = None  # Material.anisotropy and its direction in radians (None: none)
    iridescence: tuple[float, float, float] | None = None  # Material.iridescence, its film's index and nm
    # A posed entity's own batch: (entity, its Skin's skinning ("": no Skin), wearing a Morph); (0, "", False): none.
    posed: tuple[int, str, bool] = (0, "", False)
    # The maps that read the mesh's second UV set, as bits (components.rendering.second_uv_mask; 0: none).
    second_uv_maps: int = 0
    # Material.diffuse_transmission_color and diffuse_transmission (None: none)
    diffuse_transmission: tuple[float, float, float, float] | None = None
    decal: bool = False  # a decal's cut mesh (FromDecal): drawn pulled towards the eye by a depth offset
    decal_order: int = 0  # its Decal.order: decals of higher orders blended later
    parallax_depth: float = 0.0  # Material.parallax_depth with a normal map: its PARALLAX build's uniform (0: none)
    lightmap: int = 0                   # Material.lightmap's image id (0: none): its LIGHTMAP build's
    lightmap_intensity: float = 1.0     # Material.lightmap_intensity: its draws' uniform
    # Material.subsurface_radius x subsurface_scale per channel and subsurface (None: none)
    subsurface: tuple[float, float, float, float] | None = None
    # Refractive.screen: drawn after its view's copy of colour and depth (engine/render/screen_refraction.py)
    refracts_screen: bool = False
    # The waters that gather the sun whose bodies its rows reach into (engine/render/caustics.py
    # caustic_waters_of; () none): its own batch, so that only such rows are drawn with the CAUSTICS builds.
    caustic_waters: tuple[int, ...] = ()


_NOT_PREPARED = object()  # InstanceBatch.prepared_variants before its first preparing


def blend_code(batch: InstanceBatch) -> int:
    """The scene shader's ``transparent`` uniform for ``batch``: 0 opaque, 1 faded by its
    alpha whole, 2 its diffuse light alone faded (``keeps_specular``), 3 a decal's cut, faded
    whole and not drawn at all where its alpha is 0."""
    if not batch.transparent:
        return 0
    return 3 if batch.decal else 2 if batch.keeps_specular else 1


class InstanceBatch:
    """The instances of one ``BatchKey``."""

    def __init__(self, ctx: moderngl.Context, mesh: GpuMesh, texture: moderngl.Texture | None,
                 normal_map: moderngl.Texture | None = None, capacity: int = 16) -> None:
        self.ctx = ctx
        self.mesh = mesh
        self.texture = texture
        self.normal_map = normal_map
        self.rows = np.zeros(capacity, INSTANCE_DTYPE)
        self.count = 0
        self.row_of: dict[int, int] = {}
        self.entity_at: list[int] = []
        self._dirty: set[int] = set()
        self._matrix_view: np.ndarray | None = None  # _matrices' view of rows
        self._moving = 0  # rows [0, _moving) are those of instances that have moved (write_transforms)
        # Counts changes of existing rows' places (a removal's fill, a gather's swaps): the
        # last movers' rows, (layout, entities, rows, rows as a list), hold while it stands
        # (a game's movers write the same entities every frame: their rows are not looked up again).
        self._layout = 0
        self._rows_of: tuple[int, list[int], np.ndarray, list[int]] | None = None
        self._buffer = ctx.buffer(reserve=capacity * INSTANCE_DTYPE.itemsize)
        self._buffer_rows = capacity
        self._vaos: dict[int, moderngl.VertexArray] = {}
        # What the scene pass draws this batch with, by kind of pass (ScenePrograms.record): its
        # program, vertex array and uniforms, kept with the batch and gone with it.
        self.draw_records: dict[tuple, tuple] = {}
        self._max_scale = 0.0
        self._rescale = False
        # Each row's world box, kept for the rows each upload sends (a removal's moved row
        # is sent too), and their union, worked out again after an upload that sent rows:
        # what the shadows' fit reads, exact whatever came and went before.
        self._row_boxes = np.full((capacity, 2, 3), np.nan)   # NaN: a row never measured
        # And each row's model matrix as last measured: a row turned or flipped inside the
        # same box (an exact half turn of a mesh centred on its origin) changes its shadow.
        self._row_models = np.full((capacity, 16), np.nan, np.float32)
        self._box: tuple[np.ndarray, np.ndarray] | None = None
        self._box_floats: tuple[list[float], list[float]] = ([], [])  # the same, as floats (_measure_few)
        # Where instances were and are whose rows changed since ``take_changed_box`` (the old
        # and the new boxes of moved, added and removed rows that cast): what a shadow map must redraw.
        self._changed: tuple[list[float], list[float]] | None = None
        # ... and the boxes it was grown by, while there are few (None: past MAX_CHANGED_PARTS,
        # the box alone): a shadow map redraws under each, not under the box holding them all.
        self._changed_parts: list[tuple[list[float], list[float]]] | None = []
        # Some row may cast no shadow (glass, casts_shadows off, hidden everywhere: the extract
        # stage says so, ``note_row_casts``): the changed box then leaves out the rows that do
        # not (their moves change no shadow); while False no row's fields are read for it.
        self.may_not_cast = False
        self._non_casters: set[int] = set()  # the entities whose rows cast nothing (may_not_cast while any)
        self.key: BatchKey | None = None  # set by Renderer.batch_for
        # Each row's size, where this batch's mesh is a generated shape's unit mesh (Mesh.unit):
        # the row's model matrix is its world matrix times the size (set_size); ``sized`` once any is.
        self.sized = False
        self._sizes = np.ones((capacity, 3), np.float32)
        self.probe = 0  # the entity owning the reflection probe its instances sample (0: none)
        self.mirrored = False  # its instances' model matrices mirror them (drawn with the other winding)
        self.caustic_waters: tuple[int, ...] = ()  # the caustic waters its instances reach into (BatchKey's)
        # Probe blending (probe_rules.probe_blend): a second probe (0: none), and whether the
        # instances blend (their rows' ``reflect`` z and w weigh the two probes, the sky the rest).
        self.second_probe = 0
        self.probe_blend = False
        self.rest_probe = 0  # the probe taking what the weights leave (0: the sky; a curved object's own)
        self._variants: tuple[int, int, int] | None = None
        self._refracts = False   # (found with _variants)
        self._variants_stale = True
        # Drawn in the scene pass's transparent slot (blended, farthest first) instead of
        # with the opaque batches: a material whose alpha is below 1 (Renderer.batch_for).
        self.transparent = False
        # ... and its highlights and environment reflection kept whole over what shows through,
        # only its diffuse light faded by its alpha (Material.blend "transparent").
        self.keeps_specular = False
        # A transparent batch whose entity is a mirror or portal, switched off or not (water):
        # a view tree's surface, drawn before its claims and fallbacks, which find its pixels
        # by its id (slot_order.see_through_surface; the extract stage sets it).
        self.surface = False
        # Such a surface's world plane (SurfaceState.plane, set by the extract stage each
        # frame; None: not known): what orders the slot's blending by depth around it
        # (slot_order.back_to_front).
        self.plane: glm.vec4 | None = None
        # How many uploads sent rows or measured them again: what the scene pass's
        # transparent slot keeps its geometry by (scene_pass.SlotGeometry.matches).
        self.uploads = 0
        # A generated checker texture drawn analytically (scene.frag's CHECKER build): its
        # cells across the UV square, and the linear colours of the cells whose integer
        # coordinates sum even and odd (``checker_look``); None: sampled as any texture.
        self.checker: tuple[float, tuple[float, float, float], tuple[float, float, float]] | None = None
        # The material's emissive (sRGB) and metallic-roughness (linear) maps, part of the
        # batch's key like its texture (Renderer.batch_for); None: the build without them.
        self.emissive_map: moderngl.Texture | None = None
        self.metallic_roughness_map: moderngl.Texture | None = None
        # A cutout's alpha threshold (Material.alpha_cutoff; None: drawn whole): the scene and
        # shadow builds that draw it discard below it, reading its texture's alpha.
        self.alpha_cutoff: float | None = None
        # The material's occlusion map (linear; None: the build without it) and its strength,
        # part of the batch's key (Renderer.batch_for), the strength its draws' uniform.
        self.occlusion_map: moderngl.Texture | None = None
        self.occlusion_strength = 1.0
        # The occlusion is its metallic-roughness map's red channel (the same image: glTF's
        # packed occlusion-roughness-metallic texture): no map, nor sampler, of its own.
        self.occlusion_packed = False
        # The material's lightmap (sRGB; None: the build without it) and its intensity, part
        # of the batch's key (Renderer.batch_for), the intensity its draws' uniform.
        self.lightmap: moderngl.Texture | None = None
        self.lightmap_intensity = 1.0
        self.double_sided = False  # Material.double_sided: its draws turn face culling off
        self.decal = False  # a decal's cut mesh (BatchKey.decal): its draws offset their depth towards the eye
        self.decal_order = 0  # its Decal.order (BatchKey.decal_order)
        # The variants Renderer.prepare_programs last built its programs for (a marker: no
        # variants, None, is a build too, the mixed one).
        self.prepared_variants: object = _NOT_PREPARED
        # The maps that read its mesh's second UV set (BatchKey.second_uv_maps): its SECOND_UV_MAPS builds' bits.
        self.second_uv_maps = 0
        # A clear-coated material's coat (Material.clearcoat, clearcoat_roughness; None:
        # none): its CLEARCOAT build's uniform, part of the batch's key.
        self.clearcoat: tuple[float, float] | None = None
        self.unlit = False  # Material.unlit: drawn with the UNLIT_MATERIAL build, lit by nothing
        self.dielectric_f0 = (0.04, 0.04, 0.04)  # what its non-metal reflects head on (Material.reflectance,
        # specular_color), a uniform
        # A sheen (Material.sheen_color, sheen_roughness; None: none): its SHEEN build's uniform.
        self.sheen: tuple[float, float, float, float] | None = None
        # Diffuse transmission (Material.diffuse_transmission_color, its share; None: none): its
        # DIFFUSE_TRANSMISSION build's uniform.
        self.diffuse_transmission: tuple[float, float, float, float] | None = None
        # Subsurface scattering (each channel's profile distance in metres, its share; None:
        # none): its SUBSURFACE build's uniform.
        self.subsurface: tuple[float, float, float, float] | None = None
        self.dispersion = 0.0  # Refractive.dispersion (0: none): its DISPERSION build's uniform
        # Refractive.screen: a view tree's views draw it after their copy of colour and depth,
        # reading what they drew behind it (engine/render/screen_refraction.py).
        self.refracts_screen = False
        self.parallax_depth = 0.0  # Material.parallax_depth (0: none): its PARALLAX build's uniform
        # Anisotropy (Material.anisotropy; its direction in radians; None: none): its ANISOTROPY build's uniform.
        self.anisotropy: tuple[float, float] | None = None
        # A thin film (Material.iridescence, its index, thickness; None: none): IRIDESCENCE's uniform.
        self.iridescence: tuple[float, float, float] | None = None
        # A posed entity's batch (BatchKey.posed): drawn with the SKINNED builds (a Skin bends
        # it) and the MORPHED builds (it wears a Morph), its row of the pose texture (PoseRows)
        # their uniform.
        self.skinned = ""   # its Skin's skinning ("linear", "dual_quaternion"; "": no Skin bends it)
        self.morphed = False
        self.pose_row = 0
        # The model-space box its rows' world boxes are made from, and its radius about the
        # origin: its mesh's, or a posed instance's pose's (``set_local_box``).
        self.box_ends, self.box_lo, self.box_hi = mesh.box_ends, mesh.box_lo, mesh.box_hi
        self.radius = mesh.radius

    # --- rows ----------------------------------------------------------------------------
    def add(self, entity: int) -> np.void:
        """A new zeroed row for ``entity``; the caller fills it."""
        if self.count == len(self.rows):
            grown = np.zeros(len(self.rows) * 2, INSTANCE_DTYPE)
            grown[: self.count] = self.rows[: self.count]
            self.rows = grown
        row = self.count
        self.count += 1
        self.row_of[entity] = row
        self.entity_at.append(entity)
        self._dirty.add(row)
        self._variants_stale = True
        self._box = None  # the union holds the new row once it is measured
        return self.rows[row]

    def set_size(self, entity: int, size: tuple[float, float, float] | None) -> bool:
        """``entity``'s size (this batch's mesh is its shape's unit mesh: ``Mesh.unit_scale``;
        None: 1), multiplied into its model matrix from the next ``write_transforms``; whether
        it changed (its matrices must be written again)."""
        sizes = self._sizes_for(len(self.rows))
        row = self.row_of[entity]
        wanted = (1.0, 1.0, 1.0) if size is None else size
        if tuple(sizes[row].tolist()) == tuple(np.float32(v) for v in wanted):
            return False
        sizes[row] = wanted
        self.sized = self.sized or size is not None
        return True

    def _sizes_for(self, rows: int) -> np.ndarray:
        """The rows' sizes, grown to hold at least ``rows`` rows (new rows 1)."""
        if len(self._sizes) < rows:
            grown = np.ones((max(rows, len(self.rows)), 3), np.float32)
            grown[: len(self._sizes)] = self._sizes
            self._sizes = grown
        return self._sizes

    def row(self, entity: int) -> np.void:
        """The writable row of ``entity``, marked for upload."""
        index = self.row_of[entity]
        self._dirty.add(index)
        return self.rows[index]

    def write_transforms(self, entities: list[int], models: list[glm.mat4], moving: bool = False,
                         motion: ObjectMotion | None = None) -> None:
        """Write the model and normal matrices of ``entities`` (each in this batch) from their
        world matrices, all rows at once, and mark the rows for upload.

        ``moving``: they moved (not joined).  When many move (``_GATHER_AT`` or more), a row
        outside the block of moving rows at the front (``_moving``) is swapped into it, so
        the rows a frame's movers write lie together and go up in one write, not one per
        scattered row (1,000 movers among 100,000 rows: 4 writes a frame, not 1,000).  A few
        movers keep their rows: a few writes cost less than the swaps.  ``motion``: the
        movers' model matrices before and after are noted there (per-object motion blur)."""
        kept = self._rows_of
        if kept is not None and kept[0] == self._layout and kept[1] == entities:
            rows, listed = kept[2], kept[3]  # the same entities as last time, on the same rows
        else:
            index = self.row_of
            rows = np.array([index[entity] for entity in entities], np.int64)
            if moving and len(rows) >= _GATHER_AT and rows.max() >= self._moving:  # some outside the block
                self._gather(rows)
                rows = np.array([index[entity] for entity in entities], np.int64)
            listed = rows.tolist()
            self._rows_of = (self._layout, list(entities), rows, listed) if moving else None
        before = self.rows["model"][rows] if motion is not None and moving else None  # (a copy: picked by index)
        flat = None
        if self.sized:  # each model matrix times its row's size (its first three columns scaled): on arrays
            sizes = self._sizes_for(len(self.rows))[rows]
            if not (sizes == 1.0).all():
                flat = np.frombuffer(glm.array(models).to_bytes(), np.float32).reshape(-1, 4, 4).copy()
                flat[:, :3, :] *= sizes[:, :, None]
                flat = flat.reshape(-1, 16)
        if flat is None and len(models) >= _NORMALS_ON_ARRAYS:
            flat = np.frombuffer(glm.array(models).to_bytes(), np.float32).reshape(-1, 16)
        if flat is not None:
            self.rows["model"][rows] = flat
            self.rows["normal_matrix"][rows] = normal_matrices(flat)
        else:
            # A few rows: each row's model and normal matrix (its first 25 floats) packed by
            # glm and written in one go through a float view of the rows.
            data = b"".join([model.to_bytes() + glm.transpose(glm.inverse(glm.mat3(model))).to_bytes()
                             for model in models])
            self._matrices()[rows] = np.frombuffer(data, np.float32).reshape(-1, _MATRIX_FLOATS)
        if before is not None:
            motion.note(entities, before, self.rows["model"][rows])
        self._dirty.update(listed)

    def _matrices(self) -> np.ndarray:
        """The rows' model and normal matrices as one float32 array (row, 25): a view of
        ``rows`` (kept while the table is), where both are written at once."""
        view = self._matrix_view
        if view is None or view.base is not self.rows:
            view = self._matrix_view = self.rows.view(np.float32).reshape(len(self.rows), -1)[:, :_MATRIX_FLOATS]
        return view

    def _gather(self, movers: np.ndarray) -> None:
        """Grow the front block of moving rows by the ``movers`` (distinct rows) outside it:
        each mover past the grown block trades places with a row in it that is not a mover
        (all at once; the swapped rows are marked for upload)."""
        front = self._moving
        outside = movers[movers >= front]
        if not len(outside):
            return
        end = front + len(outside)
        inside = np.zeros(end - front, bool)
        inside[outside[outside < end] - front] = True
        far = outside[outside >= end]                     # movers to bring in
        free = np.flatnonzero(~inside) + front            # as many rows of the block that are not movers
        rows, entity_at, index = self.rows, self.entity_at, self.row_of
        rows[free], rows[far] = rows[far], rows[free]     # fancy indexing copies: a true exchange
        boxes = self._boxes_for(len(rows))
        boxes[free], boxes[far] = boxes[far], boxes[free]  # each row's box goes with its instance
        models = self._row_models
        models[free], models[far] = models[far], models[free]  # and its model as measured
        if self.sized:
            sizes = self._sizes_for(len(rows))
            sizes[free], sizes[far] = sizes[far], sizes[free]  # and its size
        for a, b in zip(free.tolist(), far.tolist(), strict=True):
            entity_at[a], entity_at[b] = entity_at[b], entity_at[a]
            index[entity_at[a]], index[entity_at[b]] = a, b
        self._dirty.update(free.tolist())
        self._dirty.update(far.tolist())
        self._moving = end
        self._layout += 1

    def remove(self, entity: int) -> None:
        index = self.row_of.pop(entity)
        last = self.count - 1
        cast = not self.may_not_cast or bool(self._casting(slice(index, index + 1))[0])
        if self._non_casters:
            self._non_casters.discard(entity)
            self.may_not_cast = bool(self._non_casters)
        self._layout += 1
        if index != last:
            moved = self.entity_at[last]
            self.rows[index] = self.rows[last]
            if self.sized:
                sizes = self._sizes_for(last + 1)
                sizes[index] = sizes[last]
            self.entity_at[index] = moved
            self.row_of[moved] = index
            self._dirty.add(index)
        self.entity_at.pop()
        self.count = last
        self._moving = min(self._moving, last)
        self._dirty.discard(last)
        self._rescale = True  # the largest instance may have gone: measure all rows again
        self._box = None      # and the union of the rows' boxes
        boxes = self._boxes_for(last + 1)
        if cast:  # where its shadow was
            self._note_changed(boxes[index, 0].tolist(), boxes[index, 1].tolist())
        if index != last:
            boxes[index] = boxes[last]  # the moved row's box moves with it
            self._row_models[index] = self._row_models[last]
        boxes[last] = np.nan
        self._row_models[last] = np.nan
        self._variants_stale = True

    @property
    def layout(self) -> int:
        """Counts changes of existing rows' places (a removal's fill, a gather's swaps): the
        order instances are drawn in holds while it stands (a probe face kept as drawn
        compares it, ``ProbeCaptures``)."""
        return self._layout

    def variants_changed(self) -> None:
        """Say that some row's material variants (``slots`` 0-2) were written."""
        self._variants_stale = True

    @property
    def variants(self) -> tuple[int, int, int] | None:
        """The (emissive, refract, reflect) variants every instance uses, or None when they
        differ: the scene pass draws a uniform batch with a program built for its variants."""
        if self._variants_stale:
            self._find_variants()
        return self._variants

    @property
    def see_through_paint(self) -> bool:
        """A transparent batch that dims a sun's light by its alpha (its see-through map):
        not a surface the view trees draw (a water, a see-through mirror: ``surface``) and not
        a decal's cut."""
        return self.transparent and not self.surface and not self.decal

    @property
    def refracts(self) -> bool:
        """Whether some instance refracts (its refract variant is not NONE: glass, which lets
        its share of the light through: a sun's see-through map holds it)."""
        if self._variants_stale:
            self._find_variants()
        return self._refracts

    def _find_variants(self) -> None:
        slots = self.rows["slots"][: self.count, :3]
        same = self.count and bool((slots == slots[0]).all())
        self._variants = tuple(int(v) for v in slots[0]) if same else None
        self._refracts = bool(self.count) and bool((slots[:, 1] != 0).any())   # (RefractVariant.NONE: 0)
        self._variants_stale = False

    # --- GPU -----------------------------------------------------------------------------
    @property
    def extent(self) -> float:
        """About the world radius of this batch's largest instance (mesh radius x largest
        axis scale, as of the last upload; it may overestimate after a shrink)."""
        return self.radius * self._max_scale

    def centre(self) -> glm.vec3:
        """The mean world position of the instances (what back-to-front sorting compares)."""
        if not self.count:
            return glm.vec3()
        return glm.vec3(*self.rows["model"][: self.count, 12:15].mean(axis=0).tolist())

    def _grow_scale(self, rows: np.ndarray | slice) -> None:
        """Grow the largest axis scale by ``rows``' model matrices: their axes' squared
        lengths summed in float64 from the float32 rows (as ``_measure_few`` does a row at a time)."""
        axes = self.rows["model"][rows][:, :12].reshape(-1, 3, 4)[:, :, :3].astype(np.float64)
        if len(axes):
            longest = np.einsum("ncr,ncr->nc", axes, axes).max()  # squared lengths, the largest
            self._max_scale = max(self._max_scale, float(np.sqrt(longest)))

    def _grow_box(self, rows: np.ndarray | slice) -> None:
        """Measure the world boxes of ``rows`` (just sent: indices, or a slice when they are
        one run) and forget the union.

        A row's box is that of its mesh's box corners placed by its model matrix, worked out
        axis by axis without placing the eight corners: along world axis r the lowest corner
        is the translation plus, for each model axis c, the lower of ``lo_c * M[c][r]`` and
        ``hi_c * M[c][r]`` (the sum of the smallest terms is the smallest sum; rounding is
        monotonic, so it is the same float64 number as the least of the eight corners');
        the highest likewise.  Lows and highs are worked out together, as the rows' boxes
        are kept ([row, lo/hi, axis])."""
        self._boxes_for(len(self.rows))
        written = self.rows["model"][rows]
        models = written.astype(np.float64).reshape(-1, 4, 4)  # [instance, column, row]
        terms = models[:, None, :3, :3] * self.box_ends  # [instance, lo/hi corner, column, row]
        ends = np.empty_like(terms)  # each term's lower value, then its higher one
        np.minimum(terms[:, 0], terms[:, 1], out=ends[:, 0])
        np.maximum(terms[:, 0], terms[:, 1], out=ends[:, 1])
        box = ends[:, :, 0] + ends[:, :, 1]
        box += ends[:, :, 2]
        box += models[:, None, 3, :3]
        boxes = self._row_boxes
        old = boxes[rows]
        changed = (old != box).any(axis=(1, 2))  # rewritten in place: no change
        kept = self._row_models
        changed |= (kept[rows] != written).any(axis=1)  # turned inside the same box
        kept[rows] = written
        if self.may_not_cast:
            changed &= self._casting(rows)  # a move of what casts nothing changes no shadow
        if changed.any():
            # The old boxes (NaN: never measured, left out by fmin/fmax) and the new ones.
            both = np.concatenate((old, box) if changed.all() else (old[changed], box[changed]))
            # Kept apart while few (a few movers among many rows written), as _measure_few keeps them.
            parts = [(lo, hi) for lo, hi in both.tolist() if lo[0] == lo[0]] \
                if len(both) <= MAX_CHANGED_PARTS else None
            self._note_changed(np.fmin.reduce(both[:, 0]).tolist(), np.fmax.reduce(both[:, 1]).tolist(), parts)
        boxes[rows] = box
        self._box = None

    def _measure_few(self, rows: np.ndarray | slice) -> None:
        """``_grow_scale`` and ``_grow_box`` for a few rows (``_FEW_ROWS``: a frame's handful
        of movers) in Python floats, row by row: a numpy call on a cold cache costs several
        microseconds whatever its size, and the two take some thirty of them.  The same
        float64 operations in the same order (a term's lower value is numpy's minimum, ``a``
        when ``a < b`` else ``b``; the sums c = 0 + 1, + 2, + the translation), so the boxes
        are the same numbers the array path writes; the changed box skips NaN (never
        measured) as fmin and fmax do."""
        boxes = self._boxes_for(len(self.rows))
        lo_ends, hi_ends = self.box_lo, self.box_hi
        longest = 0.0
        measured = []
        changed_lo = changed_hi = None
        union = self._box_floats if self._box is not None else None  # the rows' union, while it holds
        lx, ly, lz = lo_ends
        hx, hy, hz = hi_ends
        # Which rows cast, where some may not (a move of what casts nothing changes no shadow).
        casting = self._casting(rows).tolist() if self.may_not_cast else None
        parts: list[tuple[list[float], list[float]]] = []   # each changed row's old and new box
        written = self.rows["model"][rows]
        kept = self._row_models
        for n, (m, (old_lo, old_hi), was) in enumerate(zip(written.tolist(), boxes[rows].tolist(),
                                                           kept[rows].tolist(), strict=True)):
            # m is column-major: column c (model axis c) is m[4c:4c + 3], the translation m[12:15].
            m0, m1, m2, _, m4, m5, m6, _, m8, m9, m10, _, t0, t1, t2, _ = m
            low, high = [], []
            for x, y, z, t in ((m0, m4, m8, t0), (m1, m5, m9, t1), (m2, m6, m10, t2)):  # world axis r: M[c][r]
                a, b, c, d, e, f = x * lx, x * hx, y * ly, y * hy, z * lz, z * hz
                low.append((a if a < b else b) + (c if c < d else d) + (e if e < f else f) + t)
                high.append((a if a > b else b) + (c if c > d else d) + (e if e > f else f) + t)
            for x, y, z in ((m0, m1, m2), (m4, m5, m6), (m8, m9, m10)):
                length = x * x + y * y + z * z
                if length > longest:
                    longest = length
            measured.append((low, high))
            # NaN (never measured) differs from everything; a row turned inside the same box
            # (its model changed, its box not) changes its shadow there.
            if low != old_lo or high != old_hi or m != was:
                if union is not None and not _union_holds(union, old_lo, old_hi, low, high):
                    union = None
                if casting is not None and not casting[n]:
                    continue
                for lo_box, hi_box in ((old_lo, old_hi), (low, high)):
                    if lo_box[0] != lo_box[0]:
                        continue  # never measured
                    parts.append((lo_box, hi_box))
                    if changed_lo is None:
                        changed_lo, changed_hi = list(lo_box), list(hi_box)
                        continue
                    for i in range(3):
                        if lo_box[i] < changed_lo[i]:
                            changed_lo[i] = lo_box[i]
                        if hi_box[i] > changed_hi[i]:
                            changed_hi[i] = hi_box[i]
        if not measured:
            return
        self._max_scale = max(self._max_scale, math.sqrt(longest))
        boxes[rows] = measured
        kept[rows] = written
        if union is None:
            self._box = None  # worked out again when asked
        if changed_lo is not None:
            self._note_changed(changed_lo, changed_hi, parts)

    def _boxes_for(self, rows: int) -> np.ndarray:
        """The rows' boxes, grown to hold at least ``rows`` rows."""
        if len(self._row_boxes) < rows:
            grown = np.full((max(rows, len(self.rows)), 2, 3), np.nan)
            grown[: len(self._row_boxes)] = self._row_boxes
            self._row_boxes = grown
            models = np.full((len(grown), 16), np.nan, np.float32)
            models[: len(self._row_models)] = self._row_models
            self._row_models = models
        return self._row_boxes

    def set_local_box(self, lo: np.ndarray, hi: np.ndarray) -> None:
        """A posed instance's pose changed: [lo, hi] is the model-space box holding it
        (``skinning.posed_box``, grown by its morph targets' reach).  Where it stood counts as
        changed (its shape there is not what the shadow maps hold), and its rows are measured
        and sent again, their boxes
        from this one (a pose may reach past the mesh as modelled: culled by it, an arm
        raised above the head would vanish)."""
        for entity in self.entity_at:
            self.note_shadow_change(entity)
        self.box_ends = np.array([lo, hi], np.float64).reshape(2, 3, 1)
        self.box_lo, self.box_hi = tuple(float(v) for v in lo), tuple(float(v) for v in hi)
        # (its farthest corner from the origin: the larger end on each axis)
        self.radius = math.sqrt(sum(max(a * a, b * b) for a, b in zip(self.box_lo, self.box_hi, strict=True)))
        self._dirty.update(range(self.count))  # (their scale is their model matrix's: unchanged)

    def note_shadow_change(self, entity: int) -> None:
        """``entity``'s row changed what the shadow pass draws of it (whether it casts:
        ``shaders/shadow.vert``; its slice plane) where its box did not: its box counts as
        changed (``take_changed_box``), so the shadow maps are drawn again there.  A row not
        measured yet adds nothing: its first upload counts its box."""
        lo, hi = self._boxes_for(len(self.rows))[self.row_of[entity]].tolist()
        self._note_changed(lo, hi)

    def _casting(self, rows: np.ndarray | slice) -> np.ndarray:
        """Whether each of ``rows`` is drawn into the shadow maps, by its fields as written
        (``visibility_rules.row_casts_shadow``)."""
        slots = self.rows["slots"][rows]
        codes = (self.rows["tint"][rows, TINT_VISIBILITY] + 0.5).astype(np.int64)
        return row_casts_shadow(slots[:, 2], codes)

    def note_row_casts(self, entity: int, row: np.void) -> None:
        """The extract stage wrote ``entity``'s ``row``: while some row casts no shadow, the
        changed box reads the rows' fields (``may_not_cast``); once none does (it casts again,
        or went), it reads none."""
        code = int(row["tint"][TINT_VISIBILITY] + 0.5)
        if row_casts_shadow(row["slots"][2], code):
            self._non_casters.discard(entity)
        else:
            self._non_casters.add(entity)
        self.may_not_cast = bool(self._non_casters)

    def shadow_fields(self, row: np.void) -> tuple:
        """What of a row the shadow pass reads besides its model matrix (which moves its box):
        where it is drawn and casts (tint.w, less whether it receives shadows, which the maps
        do not hold), its refract and reflect variants, its slice, and the alpha of a cutout
        (its holes are where the colour's alpha times the texture's falls below the cutoff), of
        a see-through batch's row and of glass (the share of a light they let through)."""
        reads_alpha = self.alpha_cutoff is not None or self.transparent or int(row["slots"][1]) != 0
        return int(row["tint"][TINT_VISIBILITY] + 0.5) & ~NO_RECEIVE_BIT, int(row["slots"][1]), int(row["slots"][2]), \
            tuple(row["slice"].tolist()), float(row["color"][3]) if reads_alpha else None

    def _note_changed(self, lo: list[float], hi: list[float],
                      parts: list[tuple[list[float], list[float]]] | None = None) -> None:
        """Grow the changed box by [lo, hi] (floats; one with a NaN, never measured, adds
        nothing), made of the boxes ``parts`` (None: [lo, hi] itself): kept as floats, made
        arrays once when taken (a frame's few movers note it without a numpy call)."""
        if any(v != v for v in lo) or any(v != v for v in hi):
            return
        kept = self._changed_parts
        if kept is not None:
            kept.extend(parts if parts is not None else ((list(lo), list(hi)),))
            if len(kept) > MAX_CHANGED_PARTS:
                # Too many to keep apart: the box alone (a map redraws under all of it).
                self._changed_parts = None
        if self._changed is not None:  # numpy's minimum and maximum: a if a < b else b
            old_lo, old_hi = self._changed
            lo = [a if a < b else b for a, b in zip(lo, old_lo, strict=True)]
            hi = [a if a > b else b for a, b in zip(hi, old_hi, strict=True)]
        self._changed = (list(lo), list(hi))

    def take_changed_box(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The box holding where instances were and are whose boxes changed since the last
        call (None: none), forgotten."""
        return self.take_changes()[0]

    def take_changes(self) -> tuple[tuple[np.ndarray, np.ndarray] | None, list | None]:
        """``take_changed_box``'s box ([lo, hi] arrays) and the boxes it holds ([lo, hi]
        lists of floats, as ``shadow_rules.changed_region`` reads them: no array a part;
        None: too many to keep, the box alone), both forgotten."""
        changed, self._changed = self._changed, None
        parts, self._changed_parts = self._changed_parts, []
        if changed is None:
            return None, []
        return (np.array(changed[0]), np.array(changed[1])), parts

    @property
    def row_boxes(self) -> np.ndarray:
        """Each instance's world box as of the last upload, ``[row, lo/hi, xyz]`` (a view of
        the kept boxes, rows in ``entity_at``'s order; NaN: a row not measured yet)."""
        return self._row_boxes[: self.count]

    @property
    def box(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The world box [lo, hi] holding every instance as of the last upload (None: empty)."""
        if not self.count:
            return None
        if self._box is None:
            boxes = self._row_boxes[: self.count]
            self._box = (boxes[:, 0].min(axis=0), boxes[:, 1].max(axis=0))
            self._box_floats = (self._box[0].tolist(), self._box[1].tolist())
        return self._box

    def upload(self) -> int:
        """Send rows written since the last upload; returns the bytes sent."""
        size = INSTANCE_DTYPE.itemsize
        if self._buffer_rows < len(self.rows):
            self._buffer.orphan(len(self.rows) * size)
            self._buffer_rows = len(self.rows)
            self._dirty = set(range(self.count))
        if self._rescale:
            self._max_scale, self._rescale, self._box = 0.0, False, None
            self._grow_scale(np.arange(self.count))
            self.uploads += 1
        dirty = self._dirty
        if not dirty:
            return 0
        self._dirty = set()
        self.uploads += 1
        first, last, count = min(dirty), max(dirty), len(dirty)
        if last - first + 1 == count:
            # One run (the movers' block at the front, gathered by write_transforms): measured
            # through views of the rows, not copies picked out by index, and sent in one write.
            measured = slice(first, last + 1)
            starts, ends = [first], [last + 1]
        else:
            measured = np.fromiter(dirty, np.int64, count)
            measured.sort()
            if last + 1 - first <= _SPAN_SLACK * count:
                starts, ends = [first], [last + 1]  # the span is not much more than the rows
            else:
                breaks = np.flatnonzero(np.diff(measured) != 1) + 1
                starts = [first, *measured[breaks].tolist()]
                ends = [*(measured[breaks - 1] + 1).tolist(), last + 1]
        if count <= _FEW_ROWS:
            self._measure_few(measured)
        else:
            self._grow_scale(measured)
            self._grow_box(measured)
        sent = 0
        data = memoryview(self.rows.view(np.uint8))  # rows as bytes: a run is a slice, not a copy
        write = self._buffer.write
        for start, end in zip(starts, ends, strict=True):
            start, end = start * size, end * size
            write(data[start:end], offset=start)
            sent += end - start
        return sent

    def vao(self, program: moderngl.Program, views: int = 1) -> moderngl.VertexArray:
        """This batch's vertex array for ``program`` (made once per program, buffer and
        ``views``).  With ``views`` n > 1 its instance rows advance every n instances (the
        divisor), so a draw of count x n instances draws each row once for each of n views:
        instance i is row i / n in view i % n (the instanced-views builds: scene.vert)."""
        key = program.glo if views == 1 else (program.glo, views)
        vao = self._vaos.get(key)
        if vao is None:
            buffers = [(self.mesh.vertices, self.mesh.vertex_format, *VERTEX_ATTRIBUTES)]
            if views == 1:
                buffers.append((self._buffer, INSTANCE_FORMAT, *INSTANCE_ATTRIBUTES))
            if self.mesh.colors is not None:
                buffers.append((self.mesh.colors, "4f", "in_vertex_color"))
            if self.skinned and self.mesh.skin is not None:
                buffers.append((self.mesh.skin, "4u2 4f", "in_joints", "in_weights"))
            content = [fitted for entry in buffers if (fitted := read_by(program, *entry)) is not None]
            vao = self.ctx.vertex_array(program, content, index_buffer=self.mesh.indices, index_element_size=4)
            if views != 1:  # (moderngl's formats say only "per instance": the rows bound one input column at a time)
                for name, column, kind, layout, offset in _INSTANCE_COLUMNS:
                    if name in program:
                        vao.bind(program[name].location + column, kind, self._buffer, layout, offset=offset,
                                 stride=INSTANCE_DTYPE.itemsize, divisor=views)
            self._vaos[key] = vao
        return vao

    def drop_vertex_arrays(self) -> None:
        """Forget the vertex arrays (after a shader hot reload a relinked program may read an
        input its first build dropped, which an array made before was not given)."""
        for vao in self._vaos.values():
            vao.release()
        self._vaos.clear()
        self.draw_records.clear()

    def draw(self, program: moderngl.Program) -> None:
        if self.count:
            self.vao(program).render(moderngl.TRIANGLES, vertices=self.mesh.index_count,
                                     instances=self.count)

    def release(self) -> None:
        self.drop_vertex_arrays()
        self._buffer.release()
