"""A model file and every file it names, read by the engine itself before trimesh parses a byte.

trimesh, left to itself, opens whatever a file names: its resolver falls back to a bare file
name when the path written is not there, reads a ``data:`` URI that is not base64 as a file
name, and takes an OBJ's first ``mtllib`` even inside a comment; a FIFO put under any of those
names hangs the load.  Here every name is resolved by the engine: relative to the file that
names it, inside the allowed roots, a regular file (checked on the descriptor actually read),
within a size limit before it is read; trimesh gets the model's bytes and ``CheckedFiles``, a
resolver that hands out only the bytes read here and refuses every other name.

What trimesh is given is rewritten where it would read a file on its own: an OBJ gets one
``mtllib`` of the engine's making (the libraries it names merged, each map statement's options
parsed and its file resolved here), a glTF's unused images are blanked and its materials get
names that say their index (trimesh keeps neither the index nor ``normalTexture.scale``).

Textures a caller never draws (``textures=False``: a level file uses a model's mesh, not its
materials) are checked by name (inside the roots, a regular file, within its size limit) but
not read or decoded.
"""
from __future__ import annotations

import base64
import io
import json
import math
import os
import re
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from urllib.parse import unquote

from engine.assets.gltf_accessors import (
    BufferBytes,
    check_accessor_views,
    dense_sparse_accessors,
    float_normalized_accessors,
)
from engine.assets.gltf_animations import read_animations, read_node_tree
from engine.assets.gltf_compression import (
    decode_basisu_textures,
    decode_draco_primitives,
    decode_meshopt_views,
    missing_decoders,
)
from engine.assets.gltf_instancing import expand_gpu_instancing
from engine.assets.gltf_morphs import node_weights, read_morphs
from engine.assets.gltf_skins import read_skins
from engine.assets.gltf_uv_sets import UvPlan, plan_uv_sets, tag_uv_sets
from engine.assets.gltf_variants import apply_variant
from engine.assets.texture_data import contained_path, file_problem, read_asset_file
from engine.core.errors import AssetError

MAX_SIDE_FILE_BYTES = 256 << 20  # a glTF buffer or an image a model names, read whole before parsing
MAX_MTL_BYTES = 16 << 20  # a material library (real ones are a few KB: it is text read whole)
MAX_MODEL_BYTES = 1 << 30  # a model's file and every file it names together
MAX_JSON_NESTING = 64  # arrays and objects inside a glTF's JSON (a real one nests about 6 deep)
MAX_MTL_BUMP_SCALE = 16.0  # Material.normal_scale's limit

MTL_LIBRARY = "speculum-materials.mtl"  # the one library name trimesh is given for an OBJ


class CheckedFiles:
    """trimesh's resolver for one model: the bytes the engine read after its checks, by the
    exact name trimesh asks for, and nothing else (any other name is a FileNotFoundError,
    which trimesh takes as a missing file and the engine has already reported or allowed)."""

    def __init__(self, file_name: str) -> None:
        self.file_name = file_name  # trimesh names an unnamed OBJ part after it
        self._data: dict[str, bytes] = {}
        self.total = 0
        # Every file beside the model it names and the engine found (buffers, images, material
        # libraries and their maps): what a level reload watches as it watches the model.
        self.side_files: set[Path] = set()

    def bytes_of(self, name: str) -> bytes | None:
        """The bytes read for ``name`` (None: none were)."""
        return self._data.get(name)

    def add(self, name: str, data: bytes, what: str) -> None:
        self.total += len(data)
        if self.total > MAX_MODEL_BYTES:
            raise AssetError(f"{what}: the model's files would take more than {MAX_MODEL_BYTES >> 20} MiB "
                             "together (engine.assets.model_files.MAX_MODEL_BYTES)")
        self._data[name] = data

    def get(self, name: str) -> bytes:
        if isinstance(name, str) and name in self._data:
            return self._data[name]
        raise FileNotFoundError(f"{name!r}: not a file the engine checked")

    __getitem__ = get

    def __contains__(self, name: object) -> bool:
        return name in self._data

    def keys(self) -> list[str]:
        return list(self._data)

    def namespaced(self, namespace: str) -> CheckedFiles:
        return CheckedFiles(self.file_name)  # nothing under another folder is served

    def write(self, name: str, data: bytes) -> None:
        raise OSError("a model's resolver is read-only")


def side_file(owner: Path, name: str, roots: Sequence[Path], kind: str, owner_kind: str = "mesh file",
              max_bytes: int = MAX_SIDE_FILE_BYTES) -> Path | None:
    """The file ``owner`` names (``name``, relative to its folder; backslashes read as a
    Windows path's separators when no file has the name as written): None when nothing is
    there; an AssetError when it is outside ``roots``, not a regular file or past
    ``max_bytes``, before anything opens it for reading."""
    where = f"{owner_kind} {str(owner)!r}: its {kind} {name!r}"
    if not name or "\0" in name:
        raise AssetError(f"{where}: is not a usable file name")
    if "\\" in name and not os.path.lexists(owner.parent / name):
        name = name.replace("\\", "/")  # a path written on Windows (as other readers take it)
        where = f"{owner_kind} {str(owner)!r}: its {kind} {name!r}"
    target = owner.parent / name
    if contained_path(target, roots) is None:
        raise AssetError(f"{where} is outside the level's folder (the folders a model's files may be in: "
                         f"{', '.join(str(r) for r in roots)}): a model's files stay inside them (a game may "
                         "declare more asset roots, a player may pass --asset-root DIR, a script may give "
                         "load_model or spawn_model roots=)")
    if not os.path.lexists(target):
        return None
    problem, _ = file_problem(target, max_bytes)
    if problem is not None:
        raise AssetError(f"{where}: {problem}")
    return target


# --- OBJ and MTL -------------------------------------------------------------------------------

# MTL map options and how many values each takes (-o, -s and -t take one to three numbers);
# the file name is what follows them (it may hold spaces).
MTL_OPTION_VALUES = {"-blendu": 1, "-blendv": 1, "-bm": 1, "-boost": 1, "-cc": 1, "-clamp": 1, "-imfchan": 1,
                     "-texres": 1, "-type": 1, "-mm": 2, "-o": 3, "-s": 3, "-t": 3}
MTL_MAP_KEYS = ("map_kd", "norm", "map_bump", "bump", "map_ke", "map_d")  # the maps the engine draws
MTL_FILE_KEYS = ("map_ka", "map_kd", "map_ks", "map_ke", "map_ns", "map_d", "map_bump", "bump", "disp", "decal",
                 "norm", "map_pr", "map_pm", "map_ps", "map_aat", "map_refl")
MTL_NUMBER_KEYS = ("kd", "ka", "ks", "ke", "ns", "d", "tr", "ni")


@dataclass(frozen=True)
class MtlMap:
    """One map statement of a material library: the file (None: not there), its ``-bm``
    (None: not given), and where it was written (for errors)."""

    path: Path | None
    name: str
    bump_scale: float | None
    library: Path
    line: int
    key: str  # lower case
    written: str = ""  # the key as the library writes it

    @property
    def where(self) -> str:
        return f"material library {str(self.library)!r}: line {self.line}: {self.written or self.key}"


def mtl_map_statement(words: list[str], library: Path, number: int, roots: Sequence[Path]) -> MtlMap:
    """``key [-option values...] file``: the options read (``-bm`` kept), the file named by
    what is left (inside ``roots``, a regular file), every problem naming the library and line."""
    key = words[0].lower()
    where = f"material library {str(library)!r}: line {number}: {words[0]}"
    bump_scale, i = None, 1
    while i < len(words) - 1 and words[i].startswith("-"):
        option = words[i].lower()
        if option not in MTL_OPTION_VALUES:
            raise AssetError(f"{where}: unknown map option {words[i]!r} (known: {', '.join(MTL_OPTION_VALUES)})")
        count = MTL_OPTION_VALUES[option]
        values = words[i + 1:i + 1 + count]
        if option in ("-o", "-s", "-t"):  # one to three numbers
            taken = 0
            for word in values:
                try:
                    float(word)
                except ValueError:
                    break
                taken += 1
            values = values[:taken]
        if not values or len(values) < (2 if option == "-mm" else 1) or i + 1 + len(values) >= len(words):
            raise AssetError(f"{where}: option {words[i]} needs {count if option == '-mm' else 'a'} value"
                             f"{'s' if option == '-mm' else ''} and a file name after it")
        if option == "-bm":
            try:
                bump_scale = float(values[0])
            except ValueError:
                bump_scale = math.nan
            if not 0.0 <= bump_scale <= MAX_MTL_BUMP_SCALE:
                raise AssetError(f"{where}: -bm (the bump scale) must be a number in [0, {MAX_MTL_BUMP_SCALE:g}], "
                                 f"got {values[0]!r}")
        i += 1 + len(values)
    name = " ".join(words[i:])
    if not name:
        raise AssetError(f"{where}: names no file")
    target = side_file(library, name, roots, "image", "material library")
    return MtlMap(target, name, bump_scale, library, number, key, words[0])


@dataclass
class ObjFiles:
    """What ``prepare_obj`` found: the bytes trimesh parses, its resolver, and each used
    material's map statements by key (``map_kd``, ``norm``, ``bump``, ``map_ke``, ``map_d``)."""

    text: bytes
    resolver: CheckedFiles
    maps: dict[str, dict[str, MtlMap]] = field(default_factory=dict)


def obj_text(data: bytes) -> bytes:
    """An OBJ's bytes as trimesh reads them: CRLF as LF, a backslash at a line's end joining
    it to the next (the format's line continuation); and as other readers take them: tabs
    as spaces, no byte order mark (trimesh's own parsing splits on spaces)."""
    if data.startswith(b"\xef\xbb\xbf"):  # a UTF-8 byte order mark
        data = data[3:]
    return b"\n" + data.strip().replace(b"\r\n", b"\n").replace(b"\\\n", b"").replace(b"\t", b" ") + b"\n"


_FACE_SLOTS = (b"v", b"vt", b"vn")
_SLOT_NAMES = ("vertices", "texture coordinates", "normals")
_SLOT_KINDS = ("face index", "texture coordinate index", "normal index")


def prepare_obj(path: Path, data: bytes, roots: Sequence[Path], textures: bool) -> ObjFiles:
    """Check an OBJ the way the format allows and trimesh will read it, resolve its material
    libraries and the maps their used materials name, and build what trimesh is given.

    Face indices: 0 and text are refused; a positive index may refer forward (any of the
    file's vertices, texture coordinates or normals, wherever they are written); a negative
    one counts back from the statement (rewritten here as the absolute index it means:
    trimesh would count it from the file's end).  A face naming texture coordinates (or
    normals) in a file that has none loads without them, with one warning: what other tools
    do.  An index past the file's last element is refused."""
    text = obj_text(data)
    what = f"mesh file {str(path)!r}"
    counts = {slot: 0 for slot in _FACE_SLOTS}
    highest = {slot: (0, 0) for slot in _FACE_SLOTS}  # largest positive index and its line
    libraries: list[str] = []
    used: set[str] = set()
    edits: list[tuple[int, int, bytes]] = []  # (start, end, absolute face line) for negative indices
    stream = io.BytesIO(text)
    offset = len(stream.readline())  # the leading newline
    for number, raw in enumerate(stream, 1):
        start, offset = offset, offset + len(raw)
        line = raw.rstrip(b"\n")
        body = line.split(b"#", 1)[0] if b"#" in line else line
        words = body.split()
        if not words:
            continue
        first = words[0]
        if first in counts:
            counts[first] += 1
            if first == b"v" and len(words) < 4:
                raise AssetError(f"{what}: line {number}: a vertex is 'v x y z' (three numbers), got "
                                 f"{line.decode('utf-8', 'replace')[:60]!r}")
            if first == b"vt" and len(words) != 3:  # 'vt u [v [w]]': trimesh reads exactly two
                uv = (words[1:3] + [b"0"])[:2] if len(words) > 1 else [b"0", b"0"]
                edits.append((start, start + len(line), b"vt " + b" ".join(uv)))
            elif body is not line:  # a comment after the numbers (trimesh reads it as one)
                edits.append((start, start + len(line), body))
        elif first == b"f":
            rewritten = _check_face(what, number, words, counts, highest)
            if rewritten is not None or body is not line:
                edits.append((start, start + len(line), rewritten if rewritten is not None else body))
        elif first == b"mtllib":
            libraries += body[6:].decode("utf-8", "replace").split()
        elif first == b"usemtl" and len(words) >= 2:
            used.add(" ".join(w.decode("utf-8", "replace") for w in words[1:]))
    dropped = []
    for slot, name, kind in zip(_FACE_SLOTS, _SLOT_NAMES, _SLOT_KINDS, strict=True):
        index, number = highest[slot]
        if index > counts[slot]:
            if counts[slot] == 0 and slot != b"v":
                dropped.append(name)
                continue
            raise AssetError(f"{what}: line {number}: {kind} {index}, but {counts[slot]} {name} in the file")
    if dropped:
        warnings.warn(f"{what}: faces name {' and '.join(dropped)} the file never gives: loaded without them",
                      stacklevel=4)
    if edits:
        pieces, last = [], 0
        for start, end, line in edits:
            pieces += [text[last:start], line]
            last = end
        pieces.append(text[last:])
        text = b"".join(pieces)
    resolver = CheckedFiles(path.name)
    maps, library_text = _mtl_libraries(path, libraries, used, roots, textures, resolver)
    resolver.add(MTL_LIBRARY, library_text, what)
    return ObjFiles(f"mtllib {MTL_LIBRARY}\n".encode() + text, resolver, maps)


def _check_face(what: str, number: int, words: list[bytes], counts: dict, highest: dict) -> bytes | None:
    """One face statement checked against the elements so far (negative indices) and noted
    for the file's totals (positive ones); its absolute form when it counts back."""
    negative = False
    for token in words[1:]:
        for slot, value in zip(_FACE_SLOTS, token.split(b"/"), strict=False):
            if not value:
                continue
            try:
                index = int(value)
            except ValueError:
                raise AssetError(f"{what}: line {number}: a face index is a number, got "
                                 f"{value.decode('utf-8', 'replace')[:20]!r}") from None
            if index == 0:
                raise AssetError(f"{what}: line {number}: face index 0 (OBJ indices start at 1)")
            if index < 0:
                if -index > counts[slot]:
                    kind = _SLOT_KINDS[_FACE_SLOTS.index(slot)]
                    raise AssetError(f"{what}: line {number}: {kind} {index}, but {counts[slot]} "
                                     f"{_SLOT_NAMES[_FACE_SLOTS.index(slot)]} so far (a negative index counts back)")
                negative = True
            elif index > highest[slot][0]:
                highest[slot] = (index, number)
    if not negative:
        return None
    tokens = [b"/".join(str(counts[slot] + 1 + int(value)).encode() if value.startswith(b"-") else value
                        for slot, value in zip(_FACE_SLOTS, token.split(b"/"), strict=False))
              for token in words[1:]]
    return b"f " + b" ".join(tokens)


def _mtl_libraries(obj: Path, names: list[str], used: set[str], roots, textures: bool,
                   resolver: CheckedFiles) -> tuple[dict[str, dict[str, MtlMap]], bytes]:
    """The libraries an OBJ names, merged into one for trimesh: every statement but the map
    statements copied; a used material's ``map_Kd`` given back as a name ``resolver`` serves
    (its file read here, with ``textures``); the maps the engine draws, by used material."""
    maps: dict[str, dict[str, MtlMap]] = {}
    out: list[str] = []
    images: dict[Path, str] = {}
    for name in names:
        library = side_file(obj, name, roots, "material library", max_bytes=MAX_MTL_BYTES)
        if library is None:
            warnings.warn(f"mesh file {str(obj)!r}: material library {name!r} not found; default material used",
                          stacklevel=5)
            continue
        data = read_asset_file(library, f"mesh file {str(obj)!r}: its material library {name!r}", MAX_MTL_BYTES)
        resolver.side_files.add(library)
        material = None
        for number, line in enumerate(data.decode("utf-8", "replace").splitlines(), 1):
            words = line.split()
            key = words[0].lower() if words else ""
            if key == "newmtl" and len(words) >= 2:
                material = " ".join(words[1:])
            elif key in MTL_NUMBER_KEYS and len(words) >= 2:
                try:
                    [float(v) for v in words[1:]]
                except ValueError:
                    raise AssetError(f"material library {str(library)!r}: line {number}: "
                                     f"{words[0]} must be numbers, got {line.strip()!r}") from None
            if key in MTL_FILE_KEYS:
                if key in MTL_MAP_KEYS and material in used:
                    entry = mtl_map_statement(words, library, number, roots)
                    if entry.path is not None:
                        resolver.side_files.add(entry.path)
                    found = maps.setdefault(material, {})
                    found["bump" if key == "map_bump" else key] = entry
                    if key == "map_kd" and entry.path is not None and textures:
                        if entry.path not in images:
                            images[entry.path] = f"speculum-image-{len(images)}"
                            resolver.add(images[entry.path],
                                         read_asset_file(entry.path, f"{entry.where}: its image {entry.name!r}",
                                                         MAX_SIDE_FILE_BYTES), entry.where)
                        out.append(f"map_Kd {images[entry.path]}")
                continue  # trimesh reads no other map: nothing it could open is passed on
            out.append(line)
    for material, found in maps.items():
        for entry in found.values():
            if entry.path is None:
                raise AssetError(f"{entry.where}: its image {entry.name!r} does not exist (no such file; material "
                                 f"{material!r} looked for {str(entry.library.parent / entry.name)!r})")
    return maps, "\n".join(out).encode("utf-8")


# --- glTF --------------------------------------------------------------------------------------

GLTF_TEXTURE_SLOTS = ("baseColorTexture", "metallicRoughnessTexture", "normalTexture", "emissiveTexture",
                      "occlusionTexture")
MATERIAL_TAG = "speculum-material-"  # + index: the name trimesh is given for each material
NODE_TAG = "speculum-node-"  # + index: the name trimesh is given for each node (a part's node: its animation)


@dataclass
class GltfFiles:
    """What ``prepare_gltf`` found: the bytes trimesh parses, its resolver, the document as
    the file wrote it, and per material index its name and the images its slots name."""

    data: bytes
    resolver: CheckedFiles
    doc: dict | None
    names: list = field(default_factory=list)
    slots: dict[int, dict[str, int]] = field(default_factory=dict)
    # (material index, slot) -> why its map is left out (a third UV set and transform, or a
    # texCoord that is no set's number: drawn at another set it would land in the wrong place)
    unread: dict[tuple[int, str], str] = field(default_factory=dict)
    # material index -> the UV sets its maps read (engine/assets/gltf_uv_sets.py UvPlan): made
    # into its meshes' two sets when they are read (none: TEXCOORD_0 as it is)
    uv_plans: dict[int, UvPlan] = field(default_factory=dict)
    animations: list = field(default_factory=list)  # its clips (engine/assets/gltf_animations.py)
    node_tree: object = None                         # its nodes' parents and rest transforms (NodeTree)
    skins: list = field(default_factory=list)        # its skins (engine/assets/gltf_skins.py SkinDef)
    morphs: dict = field(default_factory=dict)       # mesh index -> its morph targets' default weights

    def node(self, trimesh_name: object) -> int | None:
        """The index of the node trimesh calls ``trimesh_name`` (None: not one of the file's)."""
        if isinstance(trimesh_name, str) and trimesh_name.startswith(NODE_TAG):
            digits = re.match(r"\d+", trimesh_name[len(NODE_TAG):])
            return int(digits.group()) if digits else None
        return None

    def node_name(self, trimesh_name: object) -> object:
        """The name the file gives the node trimesh calls ``trimesh_name`` (for messages)."""
        index = self.node(trimesh_name)
        nodes = self.doc.get("nodes") if self.doc else None
        if index is None or not isinstance(nodes, list) or index >= len(nodes) or not isinstance(nodes[index], dict):
            return trimesh_name
        return nodes[index].get("name", f"node {index}")

    def skin_of(self, node: int | None) -> int | None:
        """The skin node ``node`` bends its mesh by (None: none; read_skins checked it)."""
        nodes = self.doc.get("nodes") if self.doc else None
        if node is None or not isinstance(nodes, list) or node >= len(nodes) or not isinstance(nodes[node], dict):
            return None
        return nodes[node].get("skin") if self.skins else None

    def morph_weights(self, node: int | None) -> tuple[float, ...] | None:
        """The weights node ``node`` wears its mesh's morph targets at (None: none to wear)."""
        return node_weights(self.doc, node, self.morphs) if node is not None and self.morphs else None

    def material(self, trimesh_name: object) -> tuple[int | None, dict]:
        """The index and the file's JSON of the material trimesh calls ``trimesh_name``."""
        if isinstance(trimesh_name, str) and trimesh_name.startswith(MATERIAL_TAG):
            index = int(trimesh_name[len(MATERIAL_TAG):])
            materials = self.doc.get("materials") if self.doc else None
            return index, materials[index] if isinstance(materials, list) else {}
        return None, {}

    def label(self, index: int | None) -> str:
        name = self.names[index] if index is not None and index < len(self.names) else None
        return f"material {name!r}" if isinstance(name, str) else f"material {index}"


def _glb_json(path: Path, data: bytes) -> tuple[dict | None, int]:
    """A GLB's JSON chunk (12-byte header, then the chunk's length and type) and where the
    chunk ends; (None, 0) when it is not a GLB trimesh could read (trimesh refuses it)."""
    if len(data) < 20 or data[:4] != b"glTF" or data[16:20] != b"JSON":
        return None, 0
    length = int.from_bytes(data[12:16], "little")
    if 20 + length > len(data):
        return None, 0
    doc = _json(path, data[20:20 + length], quiet=True)
    return doc, 20 + length


def _json(path: Path, data: bytes, quiet: bool = False) -> dict | None:
    try:
        doc = json.loads(data.decode("utf-8"))
    except RecursionError:
        raise AssetError(f"mesh file {str(path)!r}: its JSON is nested too deeply (at most {MAX_JSON_NESTING})") \
            from None
    except (UnicodeDecodeError, ValueError) as exc:
        if quiet:
            return None
        raise AssetError(f"mesh file {str(path)!r}: is not a JSON glTF file ({type(exc).__name__})") from None
    deepest, stack = 0, [(doc, 1)]
    while stack:
        item, depth = stack.pop()
        deepest = max(deepest, depth)
        if deepest > MAX_JSON_NESTING:
            raise AssetError(f"mesh file {str(path)!r}: its JSON is nested too deeply (at most {MAX_JSON_NESTING})")
        children = item.values() if isinstance(item, dict) else item
        stack.extend((child, depth + 1) for child in children if isinstance(child, (dict, list)))
    return doc if isinstance(doc, dict) else None


# glTF extensions the engine reads (a texture transform: offset, rotation and scale, two sets of
# them a material: engine/assets/gltf_uv_sets.py; lights: engine/assets/model_lights.py; glass:
# transmission, ior, volume, dispersion; a clear coat; a sheen; anisotropy; a thin film; unlit; material variants:
# engine/assets/gltf_variants.py; packed vertex data: engine/assets/gltf_accessors.py;
# instancing: engine/assets/gltf_instancing.py; WebP and AVIF images; meshopt-packed data and KTX2
# images, with their optional packages: engine/assets/gltf_compression.py)
GLTF_READ_EXTENSIONS = frozenset({
    "EXT_mesh_gpu_instancing", "EXT_texture_avif", "EXT_texture_webp", "KHR_lights_punctual",
    "KHR_materials_anisotropy", "KHR_materials_diffuse_transmission",
    "KHR_materials_clearcoat", "KHR_materials_dispersion", "KHR_materials_iridescence",
    "KHR_materials_emissive_strength", "KHR_materials_ior", "KHR_materials_sheen", "KHR_materials_specular",
    "KHR_materials_transmission", "KHR_materials_variants",
    "KHR_materials_unlit", "KHR_materials_volume", "KHR_mesh_quantization", "KHR_texture_transform",
    "EXT_meshopt_compression", "KHR_texture_basisu", "KHR_draco_mesh_compression"})


def _texture_set(info: object) -> int | str:
    """The UV set a material slot's texture (its ``textureInfo``) reads: its ``texCoord``, or
    its transform's, which overrides it (KHR_texture_transform); a reason where it names none."""
    if not isinstance(info, dict):
        return 0
    transform = (info.get("extensions") or {}).get("KHR_texture_transform") \
        if isinstance(info.get("extensions"), dict) else None
    coord = transform.get("texCoord", info.get("texCoord", 0)) if isinstance(transform, dict) \
        else info.get("texCoord", 0)
    if isinstance(coord, bool) or not isinstance(coord, int) or coord < 0:
        return f"its texCoord is {coord!r}, not a UV set's number"
    return coord


def _uv_sets_lacking(doc: dict) -> Callable[[int, int], str | None]:
    """``lacking(material index, UV set number past 0)``: the first primitive drawn with that
    material that lacks that TEXCOORD_n, named (None: none lacks it); its maps reading it are
    left out (drawn at another set they would land in the wrong place)."""
    primitives = [(f"mesh {m}'s primitive {p}", primitive) for m, mesh in enumerate(doc.get("meshes") or [])
                  if isinstance(mesh, dict) for p, primitive in enumerate(mesh.get("primitives") or [])
                  if isinstance(primitive, dict) and isinstance(primitive.get("attributes"), dict)]
    have = {name: {int(a[9:]) for a in primitive["attributes"] if isinstance(a, str) and a.startswith("TEXCOORD_")
                   and a[9:].isdigit()} for name, primitive in primitives}
    highest = max((n for sets in have.values() for n in sets), default=0)
    lacking: dict[tuple[int, int], str] = {}
    for name, primitive in primitives:
        material = primitive.get("material")
        if isinstance(material, int) and not isinstance(material, bool):
            for number in range(1, highest + 2):
                if number not in have[name]:
                    lacking.setdefault((material, number), name)
    return lambda material, number: lacking.get((material, min(number, highest + 1)))


def _uv_transform(info: object, label: str) -> tuple[float, float, float, float, float] | None:
    """A slot's ``KHR_texture_transform`` as (offset x, offset y, rotation, scale x,
    scale y), checked (None: none, or one that changes nothing)."""
    extensions = info.get("extensions") if isinstance(info, dict) else None
    transform = extensions.get("KHR_texture_transform") if isinstance(extensions, dict) else None
    if transform is None:
        return None
    if not isinstance(transform, dict):
        raise AssetError(f"{label}: KHR_texture_transform must be an object, got {transform!r}")

    def numbers_of(key: str, default: list[float]) -> list[float]:
        value = transform.get(key, default)
        values = value if isinstance(value, list) else [value]
        if len(values) != len(default) or not all(
                isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and abs(v) <= 1e6
                for v in values):
            raise AssetError(f"{label}: KHR_texture_transform.{key} must be {len(default)} finite number"
                             f"{'s' if len(default) > 1 else ''}, got {value!r}")
        return [float(v) for v in values]

    (ox, oy), (rotation,), (sx, sy) = numbers_of("offset", [0.0, 0.0]), numbers_of("rotation", [0.0]), \
        numbers_of("scale", [1.0, 1.0])
    found = (ox, oy, rotation, sx, sy)
    return None if found == (0.0, 0.0, 0.0, 1.0, 1.0) else found


def _data_uri_bytes(uri: str) -> bytes | None:
    """A ``data:`` URI's bytes (glTF's are base64; None where it holds none that decode)."""
    try:
        return base64.b64decode(uri.split(",", 1)[1], validate=False)
    except (ValueError, IndexError):
        return None


def _buffer_bytes(doc: dict, number: int, resolver: CheckedFiles, chunks: memoryview) -> bytes | memoryview | None:
    """Buffer ``number``'s bytes as read: a file's (``resolver``), base64 data's, or a GLB's
    binary chunk (``chunks``: what follows its JSON chunk) for the buffer without a URI; None
    where the file has no such buffer."""
    buffers = doc.get("buffers") if isinstance(doc.get("buffers"), list) else []
    buffer = buffers[number] if 0 <= number < len(buffers) else None
    if not isinstance(buffer, dict):
        return None
    uri = buffer.get("uri")
    if isinstance(uri, str) and uri.startswith("data:"):
        return _data_uri_bytes(uri)
    if isinstance(uri, str):
        return resolver.bytes_of(uri)
    if len(chunks) >= 8 and bytes(chunks[4:8]) == b"BIN\0":
        return chunks[8:8 + int.from_bytes(chunks[0:4], "little")]
    return None


def prepare_gltf(path: Path, data: bytes, roots: Sequence[Path], textures: bool,
                 variant: str | None = None) -> GltfFiles:
    """Check a glTF's (or GLB's) JSON and resolve the buffers and images it names; the
    images its used materials draw are read (with ``textures``), the others blanked, so
    trimesh opens nothing; a missing image, a texture or image index out of range, or a
    ``data:`` URI that is not base64 is an error naming the material and the slot.
    ``variant``: the material variant its primitives wear (``gltf_variants``; None: the
    default look)."""
    what = f"mesh file {str(path)!r}"
    resolver = CheckedFiles(path.name)
    glb = path.suffix.lower() == ".glb"
    if glb:
        declared = int.from_bytes(data[8:12], "little") if len(data) >= 12 else 12
        if data[:4] == b"glTF" and declared > len(data):  # (trimesh's word for it: a bare ValueError)
            raise AssetError(f"{what}: is cut short (its GLB header says {declared} bytes, the file holds "
                             f"{len(data)})")
        doc, chunk_end = _glb_json(path, data)
        if doc is None:
            return GltfFiles(data, resolver, None)  # trimesh says what is wrong; it can open nothing
    else:
        doc = _json(path, data)
        if doc is None or "asset" not in doc:
            raise AssetError(f"{what}: is not a glTF document (no 'asset' object)")
    required = doc.get("extensionsRequired")
    if required is not None and not (isinstance(required, list) and all(isinstance(n, str) for n in required)):
        raise AssetError(f"{what}: extensionsRequired must be a list of extension names, got {required!r}")
    missing = sorted(str(name) for name in required if name not in GLTF_READ_EXTENSIONS) \
        if isinstance(required, list) else []
    missing += missing_decoders(required if isinstance(required, list) else [])
    if missing:
        raise AssetError(f"{what}: requires the glTF extension{'s' if len(missing) > 1 else ''} "
                         f"{', '.join(missing)}, which the engine does not read (glTF: a file a loader cannot "
                         "draw as it means is refused)")
    buffers = doc.get("buffers")
    for number, buffer in enumerate(buffers if isinstance(buffers, list) else ()):
        uri = buffer.get("uri") if isinstance(buffer, dict) else None
        if isinstance(uri, str):
            _uri(path, uri, roots, f"buffer {number}", resolver, True, what)
    chunks = memoryview(data)[chunk_end:] if glb else memoryview(b"")  # (a view: the binary chunk is not copied)
    read_buffers: dict[int, bytes | memoryview | None] = {}

    def buffer_bytes(number: int) -> bytes | memoryview | None:
        """Buffer ``number``'s bytes, found (a data URI decoded) once however many accessors read it."""
        if number not in read_buffers:
            read_buffers[number] = _buffer_bytes(doc, number, resolver, chunks)
        return read_buffers[number]

    decode_draco_primitives(doc, buffer_bytes, what)  # (first of all: the data the others read, made plain)
    decode_meshopt_views(doc, buffer_bytes, what)
    dense_sparse_accessors(doc, buffer_bytes, what)  # (first: a sparse normalised one is then decoded too)
    float_normalized_accessors(doc, buffer_bytes, what)
    check_accessor_views(doc, buffer_bytes, what)  # (a file cut short: named here, not trimesh's IndexError)
    expand_gpu_instancing(doc, buffer_bytes, what)
    try:
        apply_variant(doc, variant)
    except AssetError as exc:
        raise AssetError(f"{what}: {exc}") from None
    skins = read_skins(doc, buffer_bytes, what)
    tag_uv_sets(doc)
    morphs = read_morphs(doc, what)  # (before the clips: a weights channel is as wide as its mesh's targets)
    animations = read_animations(doc, buffer_bytes, what)
    materials = doc.get("materials") if isinstance(doc.get("materials"), list) else []
    textures_list = doc.get("textures") if isinstance(doc.get("textures"), list) else []
    decode_basisu_textures(doc, lambda number: _image_bytes(doc, number, buffer_bytes, path, roots, resolver, what),
                           what)
    for texture in textures_list:
        # EXT_texture_webp, EXT_texture_avif: a WebP or AVIF image (Pillow decodes both) in
        # place of the fallback "source"
        extensions = texture.get("extensions") if isinstance(texture, dict) else None
        for name in ("EXT_texture_avif", "EXT_texture_webp"):
            found = extensions.get(name) if isinstance(extensions, dict) else None
            if isinstance(found, dict) and "source" in found:
                texture["source"] = found["source"]
                break
    images = doc.get("images") if isinstance(doc.get("images"), list) else []
    used_materials = {primitive.get("material") for mesh in (doc.get("meshes") or [])
                      if isinstance(mesh, dict) for primitive in (mesh.get("primitives") or [])
                      if isinstance(primitive, dict)}
    lacking = _uv_sets_lacking(doc)
    result = GltfFiles(b"", resolver, doc, [m.get("name") if isinstance(m, dict) else None for m in materials])
    result.animations = animations
    result.skins = skins
    result.morphs = morphs
    wanted: dict[int, tuple[str, str]] = {}  # image index -> (material label, slot)
    for index, material in enumerate(materials):
        if not isinstance(material, dict) or index not in used_materials:
            continue
        pbr = material.get("pbrMetallicRoughness") if isinstance(material.get("pbrMetallicRoughness"), dict) else {}
        emissive = material.get("emissiveFactor", [0.0, 0.0, 0.0])
        if not (isinstance(emissive, list) and len(emissive) == 3 and all(
                isinstance(e, (int, float)) and not isinstance(e, bool) and 0.0 <= e <= 65504.0 for e in emissive)):
            raise AssetError(f"{what}: {result.label(index)}: emissiveFactor must be three numbers in [0, 65504], "
                             f"got {emissive!r}")
        # Each map's UV set and transform, grouped into the mesh's two sets (gltf_uv_sets.py)
        uses, unread = {}, {}
        for slot in GLTF_TEXTURE_SLOTS:
            info = pbr.get(slot, material.get(slot))
            if info is not None:
                transform = _uv_transform(info, f"{what}: {result.label(index)}: {slot}")
                coord = _texture_set(info)
                if isinstance(coord, str):
                    unread[slot] = coord
                elif coord > 0 and (where := lacking(index, coord)) is not None:
                    unread[slot] = f"it reads TEXCOORD_{coord}, which {where} does not have"
                else:
                    uses[slot] = (coord, transform)
        plan, left_out = plan_uv_sets(uses)
        unread.update(left_out)
        if plan is not None:
            result.uv_plans[index] = plan
        for slot in GLTF_TEXTURE_SLOTS:
            info = pbr.get(slot, material.get(slot))
            if info is None:
                continue
            label = f"{what}: {result.label(index)}: {slot}"
            if slot in unread:
                result.unread[(index, slot)] = unread[slot]
                warnings.warn(f"{label}: {unread[slot]}: the map is left out", stacklevel=4)
                continue
            texture_index = info.get("index") if isinstance(info, dict) else None
            if not _index_in(texture_index, textures_list) or not isinstance(textures_list[texture_index], dict):
                raise AssetError(f"{label}: names texture {texture_index!r}, which the file does not have")
            source = textures_list[texture_index].get("source")
            if not _index_in(source, images) or not isinstance(images[source], dict):
                raise AssetError(f"{label}: texture {texture_index} names image {source!r}, which the file "
                                 "does not have")
            result.slots.setdefault(index, {})[slot] = source
            wanted.setdefault(source, (result.label(index), slot))
    for number, image in enumerate(images):
        uri = image.get("uri") if isinstance(image, dict) else None
        if number in wanted and isinstance(uri, str):
            label, slot = wanted[number]
            _uri(path, uri, roots, f"{label}: {slot}: image {number}", resolver, textures, what)
        if number not in wanted or not textures:
            images[number] = {}  # trimesh skips it: nothing read, nothing decoded
    for index, material in enumerate(materials):
        if isinstance(material, dict):
            material["name"] = f"{MATERIAL_TAG}{index}"
    nodes = doc.get("nodes") if isinstance(doc.get("nodes"), list) else []
    node_names = [node.get("name") if isinstance(node, dict) else None for node in nodes]
    for index, node in enumerate(nodes):
        if isinstance(node, dict):
            node["name"] = f"{NODE_TAG}{index}"
    text = json.dumps(doc).encode("utf-8")
    if glb:
        text += b" " * (-len(text) % 4)
        rest = data[chunk_end:]
        result.data = (b"glTF" + data[4:8] + (12 + 8 + len(text) + len(rest)).to_bytes(4, "little")
                       + len(text).to_bytes(4, "little") + b"JSON" + text + rest)
    else:
        result.data = text
    for index, material in enumerate(materials):  # as the file wrote them (trimesh parses its own copy)
        if isinstance(material, dict):
            material["name"] = result.names[index]
    for node, name in zip(nodes, node_names, strict=True):
        if isinstance(node, dict):
            if name is None:
                del node["name"]
            else:
                node["name"] = name
    if animations or skins:  # (its nodes' rest transforms: what the clips' poses and the skins start from)
        result.node_tree = read_node_tree(doc, what)
    return result


def _image_bytes(doc: dict, number: int, buffer_bytes: BufferBytes, path: Path, roots, resolver: CheckedFiles,
                 what: str) -> bytes | memoryview | None:
    """Image ``number``'s bytes: its view's (checked against its buffer), its base64 data's,
    or its file's (found and read as any side file); None where it names none."""
    image = doc["images"][number] if isinstance(doc["images"][number], dict) else {}
    uri, view = image.get("uri"), image.get("bufferView")
    if isinstance(uri, str) and uri.startswith("data:"):
        return _data_uri_bytes(uri)
    if isinstance(uri, str):
        _uri(path, uri, roots, f"image {number}", resolver, True, what)
        return resolver.bytes_of(uri)
    views = doc.get("bufferViews") if isinstance(doc.get("bufferViews"), list) else []
    if not _index_in(view, views) or not isinstance(views[view], dict):
        return None
    entry = views[view]
    data = buffer_bytes(entry.get("buffer", 0)) if isinstance(entry.get("buffer", 0), int) else None
    start, length = entry.get("byteOffset", 0), entry.get("byteLength", 0)
    if data is None or not all(isinstance(v, int) and v >= 0 for v in (start, length)) or start + length > len(data):
        raise AssetError(f"{what}: image {number}: its bufferView {view} lies outside its buffer")
    return data[start:start + length]


def _index_in(index, items: list) -> bool:
    return isinstance(index, int) and not isinstance(index, bool) and 0 <= index < len(items)


_BASE64 = re.compile(r"^data:[^,]*;base64,", re.IGNORECASE)


def _uri(path: Path, uri: str, roots, label: str, resolver: CheckedFiles, read: bool, what: str) -> None:
    """A buffer's or image's URI: base64 data (trimesh decodes it), or a file checked (and
    read into ``resolver`` under the URI as written, with ``read``); a missing file, or a
    ``data:`` URI of another kind, is an error naming ``label``."""
    if uri.startswith("data:"):
        if not _BASE64.match(uri) and "base64," not in uri:
            raise AssetError(f"{what}: {label}: a data: URI that is not base64 (glTF's data URIs are base64)")
        return
    name = unquote(uri)
    target = side_file(path, name, roots, label)
    if target is None:
        raise AssetError(f"{what}: {label}: its file {name!r} does not exist (looked for "
                         f"{str(path.parent / name)!r})")
    resolver.side_files.add(target)
    if read:
        resolver.add(uri, read_asset_file(target, f"{what}: {label}: its file {name!r}", MAX_SIDE_FILE_BYTES), what)
