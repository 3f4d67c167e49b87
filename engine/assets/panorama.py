"""Panoramas as skies: an equirectangular image made into a ``Skybox``'s six faces (three.js's
``RGBELoader`` with ``EquirectangularReflectionMapping``, Godot's ``PanoramaSkyMaterial``,
Unity's HDRI sky), so a photographed or rendered sky lights the scene, its reflections and its
probes as a cube map sky does.

Files: Radiance ``.hdr`` (RGBE or XYZE, the new run-length encoding or flat, as Greg Ward's
format writes them: ``load_hdr``) or OpenEXR ``.exr`` (``engine/assets/exr_image.py``), linear
light, the camera's exposure deciding how bright; or
any image Pillow reads (PNG, JPEG), taken as sRGB and made linear (an 8-bit panorama holds no
sun brighter than white: its light is the sky's diffuse only).

The image wraps about the eye as the engine's other panoramas do (an all-round lamp's cookie,
``engine/rules/light_rules.py`` ``lamp_cookie``): longitude across, its middle column ahead
(-Z), a quarter to the right +X; latitude up, its top row straight up (+Y).  ``yaw`` turns it
about +Y (degrees; 90 brings the image's middle round to the left, -X, as ``yaw_pitch_rotation``
turns a camera), so the sun in a panorama is put where the scene's DirectionalLight comes
from.  The panorama is box-filtered down (2 x 2 means) until it is at most eight texels a
face texel across, then each face texel averages a grid of bilinear taps over its footprint,
so a large panorama made into small faces keeps a small sun's light (no texel is skipped).

``sky_faces_from_file`` returns ``SkyFaces``: the faces as a float32 array that remembers how
they were made (``source``), so a level file that named a panorama writes it back.
"""
from __future__ import annotations

import math
import os
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from engine.assets.exr_image import load_exr_environment
from engine.assets.panorama_sun import SUN_CONTRAST, PanoramaSun, find_sun
from engine.assets.texture_data import MAX_TEXTURE_SIDE, check_asset_file, colour_image, load_texture
from engine.core.color import srgb_to_linear, xyz_to_rec709_matrix
from engine.core.cube_faces import face_directions
from engine.core.errors import AssetError

MAX_PANORAMA_FILE_BYTES = 1 << 30   # a panorama file's size on disk
# Pixels a panorama may have: an 8K HDRI's 8192 x 4096, about 400 MiB of float32 colour while it
# is made into faces (a run-length file declares its size in a few bytes: checked before any pixel).
MAX_PANORAMA_PIXELS = 8192 * 4096
MAX_FACE_SIZE = 2048                # a Skybox face's side (components.rendering's check)
FACE_SIZE = 256                     # a face's side where none is given
MAX_FOOTPRINT_TAPS = 8              # bilinear taps a side per face texel at most
MAX_INTENSITY = 1e4                 # what a panorama's colours may be multiplied by
_XYZ_TO_RGB = xyz_to_rec709_matrix()  # an XYZE file's colours to the engine's linear Rec. 709 (D65)


class SkyFaces(np.ndarray):
    """Six float32 cube faces (6, n, n, 3) that remember how they were made: ``source``, a dict
    a level file writes as the Skybox's ``faces`` table (``{ panorama = "x.hdr", face_size = n,
    yaw = degrees }``), and, made ``without_sun``, the sun taken out of them (``sun``).  A view
    of it or anything numpy makes from it has no source."""

    source: dict[str, Any] | None = None
    sun: PanoramaSun | None = None   # the sun taken out of them (``without_sun``), as a light's fields

    def __array_finalize__(self, obj: Any) -> None:
        self.source = None   # (a view or a result of arithmetic no longer is the file's faces)
        self.sun = None


def _header(data: bytes, what: str) -> tuple[dict[str, str], float, str, int]:
    """A Radiance file's header: its variables, the product of its EXPOSURE lines, its
    resolution string, and where its pixels start."""
    if not (data.startswith(b"#?RADIANCE") or data.startswith(b"#?RGBE")):
        raise AssetError(f"{what}: not a Radiance .hdr file (it does not start with #?RADIANCE or #?RGBE)")
    end = data.find(b"\n\n")
    if end < 0:
        raise AssetError(f"{what}: its header never ends (no empty line before the resolution)")
    variables: dict[str, str] = {}
    exposure = 1.0
    for line in data[:end].split(b"\n")[1:]:
        text = line.decode("latin-1").strip()
        if "=" in text and not text.startswith("#"):
            key, _, value = text.partition("=")
            if key.strip() == "EXPOSURE":
                try:
                    exposure *= float(value)
                except ValueError:
                    raise AssetError(f"{what}: EXPOSURE={value.strip()!r} is not a number") from None
            else:
                variables[key.strip()] = value.strip()
    newline = data.find(b"\n", end + 2)
    if newline < 0:
        raise AssetError(f"{what}: no resolution line after the header")
    return variables, exposure, data[end + 2:newline].decode("latin-1").strip(), newline + 1


def _resolution(text: str, what: str) -> tuple[int, int, bool, bool]:
    """(height, width, rows run bottom up, columns run right to left) from ``-Y H +X W``."""
    parts = text.split()
    if len(parts) != 4 or parts[0][1:] != "Y" or parts[2][1:] != "X" or parts[0][0] not in "+-" \
            or parts[2][0] not in "+-":
        raise AssetError(f"{what}: resolution {text!r} is not '-Y height +X width' (or its mirrorings): "
                         "a panorama stored in columns (X first) is not read")
    try:
        height, width = int(parts[1]), int(parts[3])
    except ValueError:
        raise AssetError(f"{what}: resolution {text!r} has a size that is not a whole number") from None
    if not (1 <= width <= MAX_TEXTURE_SIDE and 1 <= height <= MAX_TEXTURE_SIDE):
        raise AssetError(f"{what}: {width}x{height} pixels; a panorama may be 1 to {MAX_TEXTURE_SIDE} a side")
    if width * height > MAX_PANORAMA_PIXELS:
        raise AssetError(f"{what}: {width}x{height} pixels, more than the {MAX_PANORAMA_PIXELS} (8192x4096) a "
                         "panorama may have: scale it down")
    return height, width, parts[0][0] == "+", parts[2][0] == "-"


def _scanline(data: bytes, at: int, width: int, what: str, row: int) -> tuple[np.ndarray, int]:
    """One row of RGBE bytes (width, 4) from ``at``, and where the next starts: the new
    run-length encoding (each of the four channels in runs: a count over 128 repeats the next
    byte count - 128 times, else that many bytes follow) or, where the row does not start with
    2, 2 and its width, flat bytes."""
    head = data[at:at + 4]
    if len(head) < 4:
        raise AssetError(f"{what}: the pixels end at row {row} of its rows (the file is cut short)")
    if not (8 <= width <= 0x7FFF and head[0] == 2 and head[1] == 2 and (head[2] << 8 | head[3]) == width):
        flat = np.frombuffer(data, np.uint8, 4 * width, at) if len(data) >= at + 4 * width else None
        if flat is None:
            raise AssetError(f"{what}: the pixels end at row {row} of its rows (the file is cut short)")
        flat = flat.reshape(width, 4)
        if ((flat[:, 0] == 1) & (flat[:, 1] == 1) & (flat[:, 2] == 1)).any():
            raise AssetError(f"{what}: row {row} uses the old run-length encoding (pixels 1, 1, 1, n), which is "
                             "not read: save it again with a current writer")
        return flat, at + 4 * width
    at += 4
    row_bytes = np.empty((4, width), np.uint8)
    for channel in range(4):
        filled = 0
        while filled < width:
            if at >= len(data):
                raise AssetError(f"{what}: the pixels end at row {row} of its rows (the file is cut short)")
            count = data[at]
            at += 1
            if count > 128:
                count -= 128
                if filled + count > width or at >= len(data):
                    raise AssetError(f"{what}: row {row}'s run of {count} passes its width {width} (corrupt)")
                row_bytes[channel, filled:filled + count] = data[at]
                at += 1
            else:
                if count == 0 or filled + count > width or at + count > len(data):
                    raise AssetError(f"{what}: row {row}'s run of {count} bytes is corrupt")
                row_bytes[channel, filled:filled + count] = np.frombuffer(data, np.uint8, count, at)
                at += count
            filled += count
    return row_bytes.T, at


def load_hdr(path: str | Path) -> np.ndarray:
    """A Radiance ``.hdr`` file's pixels, (height, width, 3) float32 linear RGB, row 0 at the
    top: each RGBE (or XYZE, made RGB) pixel as Radiance's ``colr_color`` reads it, (m + 0.5)
    2^(e - 136), 0 where e is 0, divided by the header's EXPOSURE."""
    if isinstance(path, bytes) or not isinstance(path, (str, os.PathLike)):
        raise AssetError(f"panorama file path must be a str or pathlib.Path, got {type(path).__name__} {path!r}")
    path = Path(path)
    what = f"panorama file {str(path)!r}"
    check_asset_file(path, what, MAX_PANORAMA_FILE_BYTES)
    data = path.read_bytes()
    variables, exposure, resolution, at = _header(data, what)
    form = variables.get("FORMAT", "32-bit_rle_rgbe")
    if form not in ("32-bit_rle_rgbe", "32-bit_rle_xyze"):
        raise AssetError(f"{what}: FORMAT={form} is neither 32-bit_rle_rgbe nor 32-bit_rle_xyze")
    if not (math.isfinite(exposure) and exposure > 0.0):
        raise AssetError(f"{what}: its EXPOSURE lines multiply to {exposure}, not a positive number")
    height, width, bottom_up, right_to_left = _resolution(resolution, what)
    rows = np.empty((height, width, 4), np.uint8)
    for row in range(height):
        rows[row], at = _scanline(data, at, width, what, row)
    exponent = rows[..., 3].astype(np.int32)
    scale = np.where(exponent > 0, np.ldexp(np.float32(1.0), exponent - 136), np.float32(0.0)).astype(np.float32)
    pixels = (rows[..., :3].astype(np.float32) + np.float32(0.5)) * scale[..., None]   # (exact in float32)
    if exposure != 1.0:
        pixels /= np.float32(exposure)
    if form == "32-bit_rle_xyze":
        pixels = np.maximum(pixels @ _XYZ_TO_RGB.T.astype(np.float32), np.float32(0.0))
    if bottom_up:
        pixels = pixels[::-1]
    if right_to_left:
        pixels = pixels[:, ::-1]
    if not np.isfinite(pixels).all() or pixels.max(initial=0.0) > 65504.0:
        raise AssetError(f"{what}: holds colours past 65504, more than the half floats a sky's faces keep")
    return np.ascontiguousarray(pixels, np.float32)


def save_hdr(path: str | Path, image: np.ndarray) -> Path:
    """Write linear colours (height, width, 3; row 0 at the top; finite, >= 0) as a Radiance
    ``.hdr`` file (flat RGBE scanlines, as every reader takes them): each pixel its largest
    channel's exponent and three 8-bit mantissas (Radiance's ``setcolr``: within 1/256 of the
    largest channel), to bake a generated sky, a capture or a lightmap for other tools.
    Returns the path."""
    pixels = colour_image(image, "save_hdr")
    if pixels.min() < 0.0:
        raise ValueError("save_hdr: colours must be finite and >= 0")
    largest = pixels.max(axis=-1)
    mantissa, exponent = np.frexp(largest)
    scale = np.where(largest > 1e-32, mantissa * 256.0 / np.where(largest > 1e-32, largest, 1.0), 0.0)
    rgbe = np.zeros(pixels.shape[:2] + (4,), np.uint8)
    rgbe[..., :3] = np.clip(np.floor(pixels * scale[..., None]), 0, 255)
    rgbe[..., 3] = np.where(largest > 1e-32, np.clip(exponent + 128, 0, 255), 0)
    height, width = pixels.shape[:2]
    path = Path(path)
    path.write_bytes(f"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y {height} +X {width}\n".encode() + rgbe.tobytes())
    return path


def load_panorama(path: str | Path, layer: str | None = None) -> np.ndarray:
    """An equirectangular image's linear colours (height, width, 3) float32, row 0 at the top:
    a ``.hdr`` file as ``load_hdr`` reads it, an ``.exr`` file as ``load_exr`` does (``layer``:
    its part or layer of that name; a cube-map environment made a panorama by
    ``cube_map_panorama``, a latlong one turned into the engine's wrap by
    ``latlong_panorama``), any other image through Pillow as sRGB."""
    suffix = Path(path).suffix.lower()
    if suffix == ".exr":
        image, kind = load_exr_environment(path, layer)
        if kind == "cube":
            return cube_map_panorama(image)
        return latlong_panorama(image) if kind == "latlong" else image
    if layer is not None:
        raise AssetError(f"panorama file {str(path)!r}: layer {layer!r} given, but only an OpenEXR (.exr) file "
                         "has layers")
    if suffix in (".hdr", ".pic", ".rgbe"):
        return load_hdr(path)
    texture = load_texture(path)
    return srgb_to_linear(texture.pixels[..., :3] / 255.0).astype(np.float32)


def cube_map_panorama(faces: np.ndarray) -> np.ndarray:
    """An OpenEXR cube-map environment (N x 6N pixels: its faces +X, -X, +Y, -Y, +Z, -Z from
    the top, laid out as ``ImfEnvmap.h`` draws them) as an equirectangular panorama of 4N x 2N
    in the engine's wrap (the middle column -Z, a quarter to the right +X, the top row +Y):
    each pixel's direction found on its face as OpenEXR's ``CubeMap::faceAndPixelPosition``
    finds it (a face's first and last pixel centres on the cube's edges: positions scaled by
    N - 1) and read there bilinearly, within the face.  The environment's axes are the
    world's (+Y up)."""
    image = np.asarray(faces, np.float32)
    size = image.shape[1]
    height, width = 2 * size, 4 * size
    longitude = ((np.arange(width) + 0.5) / width - 0.5) * 2.0 * math.pi
    latitude = (0.5 - (np.arange(height) + 0.5) / height) * math.pi
    lat, lon = np.meshgrid(latitude, longitude, indexing="ij")
    d = np.stack([np.cos(lat) * np.sin(lon), np.sin(lat), -np.cos(lat) * np.cos(lon)], axis=-1)
    major = np.argmax(np.abs(d), axis=-1)             # the axis whose face it meets (x before y before z)
    along = np.take_along_axis(d, major[..., None], axis=-1)[..., 0]
    face = 2 * major + (along < 0.0)                    # CUBEFACE_POS_X, NEG_X, POS_Y, ... NEG_Z
    # Its position in the face (faceAndPixelPosition): the other two axes over the major one.
    first = np.where(major == 0, d[..., 1], d[..., 0]) / np.abs(along)
    second = np.where(major == 2, d[..., 1], d[..., 2]) / np.abs(along)
    px, py = (first + 1.0) / 2.0 * (size - 1), (second + 1.0) / 2.0 * (size - 1)
    # The face's pixel (pixelPosition): x across, y down within its N rows.
    last = size - 1
    x = np.select([face == 0, face == 1, face == 4], [py, last - py, last - px], px)
    y = np.select([face == 3], [py], last - np.where(face < 2, px, py))
    return _face_bilinear(image, face, x, y)


def latlong_panorama(image: np.ndarray) -> np.ndarray:
    """An OpenEXR latlong environment (``envmap`` latlong) resampled into the engine's wrap, the
    same size.  ``ImfEnvmap.h``'s ``latLong`` puts the first and last pixel centres on the
    edges (longitude +pi at the left column to -pi at the right, 0 at the middle pointing +Z,
    +pi/2 +X; latitude +pi/2 on the top row, -pi/2 on the bottom), where the engine's pixel
    centres are half a pixel in and its middle column points -Z: each engine pixel's direction
    is found in the file (a column period of width - 1: the seam's column is there twice) and
    read bilinearly."""
    image = np.asarray(image, np.float32)
    height, width = image.shape[:2]
    x = ((np.arange(width) + 0.5) / width + 0.5) % 1.0 * (width - 1)   # longitude pi - engine's, as a column
    y = (np.arange(height) + 0.5) / height * (height - 1)

    def taps(at: np.ndarray, size: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        first = np.minimum(np.floor(at).astype(np.int64), size - 1)
        return first, np.minimum(first + 1, size - 1), (at - first).astype(np.float32)

    x0, x1, fx = taps(x, width)
    y0, y1, fy = taps(y, height)
    across = image[:, x0] * (1.0 - fx)[None, :, None] + image[:, x1] * fx[None, :, None]
    return (across[y0] * (1.0 - fy)[:, None, None] + across[y1] * fy[:, None, None]).astype(np.float32)


def _face_bilinear(image: np.ndarray, face: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The stacked faces at continuous pixel coordinates ``x``, ``y`` (centres at whole
    numbers) of face ``face``, clamped to that face's pixels."""
    size = image.shape[1]
    x, y = np.clip(x, 0.0, size - 1.0), np.clip(y, 0.0, size - 1.0)
    left, top = np.floor(x), np.floor(y)
    fx, fy = (x - left)[..., None], (y - top)[..., None]
    x0, y0 = left.astype(np.int64), top.astype(np.int64)
    x1, y1 = np.minimum(x0 + 1, size - 1), np.minimum(y0 + 1, size - 1)
    row = face * size
    return ((image[row + y0, x0] * (1 - fx) + image[row + y0, x1] * fx) * (1 - fy)
            + (image[row + y1, x0] * (1 - fx) + image[row + y1, x1] * fx) * fy).astype(np.float32)


def panorama_faces(panorama: np.ndarray, face_size: int = FACE_SIZE, yaw: float = 0.0) -> np.ndarray:
    """Six cube faces (6, face_size, face_size, 3) float32 of an equirectangular panorama
    (height, width, 3; longitude across, latitude up, the middle column ahead at -Z) turned
    ``yaw`` degrees about +Y, each texel the mean of a grid of bilinear taps over its
    footprint (up to ``MAX_FOOTPRINT_TAPS`` a side) in the panorama box-filtered down to at most
    eight texels a face texel."""
    image = np.asarray(panorama, np.float32)
    if image.ndim != 3 or image.shape[2] != 3 or image.shape[0] < 1 or image.shape[1] < 1:
        raise ValueError(f"a panorama is an (height, width, 3) image, got shape {image.shape}")
    if not np.isfinite(image).all() or image.min() < 0.0:
        raise ValueError("a panorama holds finite, non-negative linear colours")
    if not (isinstance(face_size, int) and 1 <= face_size <= MAX_FACE_SIZE):
        raise ValueError(f"face_size must be an int from 1 to {MAX_FACE_SIZE}, got {face_size!r}")
    if not math.isfinite(yaw):
        raise ValueError(f"yaw must be a finite number of degrees, got {yaw!r}")
    while image.shape[1] > 8 * face_size and image.shape[0] > 1:   # box-filtered down first: no texel is skipped
        image = _halved(image)
    height, width = image.shape[:2]
    taps = int(min(MAX_FOOTPRINT_TAPS, max(1, math.ceil(width / (4.0 * face_size)))))
    turn = math.radians(yaw)
    faces = np.zeros((6, face_size, face_size, 3), np.float64)
    for face in range(6):
        for i in range(taps):
            for j in range(taps):
                # A tap's direction: the texel grid of a face taps x taps finer, every taps-th centre.
                fine = face_directions(face, face_size * taps)[i::taps, j::taps]
                x = fine[..., 0] * math.cos(turn) - fine[..., 2] * math.sin(turn)
                z = fine[..., 0] * math.sin(turn) + fine[..., 2] * math.cos(turn)
                u = 0.5 + np.arctan2(x, -z) / (2.0 * math.pi)
                v = 0.5 - np.arcsin(np.clip(fine[..., 1], -1.0, 1.0)) / math.pi
                faces[face] += _bilinear(image, u * width - 0.5, v * height - 0.5)
    return (faces / (taps * taps)).astype(np.float32)


def _halved(image: np.ndarray) -> np.ndarray:
    """Each 2 x 2 block of pixels averaged (an odd side's last row or column repeated)."""
    height, width = image.shape[:2]
    padded = np.pad(image, ((0, height % 2), (0, width % 2), (0, 0)), mode="edge")
    return padded.reshape(padded.shape[0] // 2, 2, padded.shape[1] // 2, 2, 3).mean(axis=(1, 3), dtype=np.float64)


def _bilinear(image: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The image at continuous pixel coordinates (centres at whole numbers), wrapping across
    (longitude) and clamped down (latitude)."""
    height, width = image.shape[:2]
    left, top = np.floor(x), np.floor(y)
    fx, fy = (x - left)[..., None], (y - top)[..., None]
    x0 = left.astype(np.int64) % width
    x1 = (x0 + 1) % width
    y0 = np.clip(top.astype(np.int64), 0, height - 1)
    y1 = np.clip(top.astype(np.int64) + 1, 0, height - 1)
    return ((image[y0, x0] * (1 - fx) + image[y0, x1] * fx) * (1 - fy)
            + (image[y1, x0] * (1 - fx) + image[y1, x1] * fx) * fy)


def sky_faces_from_file(path: str | Path, face_size: int = FACE_SIZE, yaw: float = 0.0,
                        intensity: float = 1.0, without_sun: bool = False, layer: str | None = None) -> SkyFaces:
    """A panorama file (``load_panorama``) as a Skybox's ``faces`` (``panorama_faces``), its
    colours times ``intensity`` (three.js's ``environmentIntensity``, Godot's sky energy: a
    photographed sky is as bright as its camera exposed it), remembering the file, size, turn
    and intensity (``SkyFaces.source``).  ``without_sun``: the panorama's sun taken out first
    (``engine.assets.panorama_sun.find_sun``) and kept as ``SkyFaces.sun``, a
    ``DirectionalLight``'s fields (None if it has no sun), so it casts shadows and is not
    counted twice.  ``layer``: an OpenEXR file's part or layer of that name (``load_exr``)."""
    if not (isinstance(intensity, (int, float)) and math.isfinite(intensity) and 0.0 <= intensity <= MAX_INTENSITY):
        raise ValueError(f"intensity must be a number from 0 to {MAX_INTENSITY:g}, got {intensity!r}")
    if not isinstance(without_sun, bool):
        raise ValueError(f"without_sun must be True or False, got {without_sun!r}")
    panorama, sun = load_panorama(path, layer), None
    if without_sun:
        sun, panorama = find_sun(panorama, yaw)
    faces = panorama_faces(panorama, face_size, yaw)
    if intensity != 1.0:
        faces *= np.float32(intensity)
        if faces.max(initial=0.0) > 65504.0:
            raise AssetError(f"panorama file {str(path)!r}: times {intensity:g} its brightest texel passes 65504, "
                             "more than the half floats a sky's faces keep")
    faces = faces.view(SkyFaces)
    # (what was given past the defaults, as a level file's table names it: a level saved writes
    # back the table it read)
    faces.source = {"panorama": str(Path(path).resolve())}
    if face_size != FACE_SIZE:
        faces.source["face_size"] = face_size
    if yaw != 0.0:
        faces.source["yaw"] = float(yaw)
    if intensity != 1.0:
        faces.source["intensity"] = float(intensity)
    if layer is not None:
        faces.source["layer"] = layer
    if without_sun:
        faces.source["without_sun"] = True
        if sun is not None:
            faces.sun = replace(sun, intensity=sun.intensity * float(intensity))
    return faces


def main(argv: list[str] | None = None) -> int:
    """``python -m engine.assets.panorama FILE [--yaw DEGREES] [--intensity X]``: prints the
    panorama's sun (``engine.assets.panorama_sun.find_sun``) as a level file's
    ``DirectionalLight`` line, to paste beside a Skybox whose faces table says
    ``without_sun = true``."""
    import argparse

    parser = argparse.ArgumentParser(prog="python -m engine.assets.panorama", description=main.__doc__)
    parser.add_argument("file")
    parser.add_argument("--yaw", type=float, default=0.0, help="the panorama's turn about up, degrees")
    parser.add_argument("--intensity", type=float, default=1.0, help="what the panorama's colours are multiplied by")
    parser.add_argument("--layer", default=None, help="an OpenEXR file's part or layer to read")
    args = parser.parse_args(argv)
    try:
        sun, _ = find_sun(load_panorama(args.file, args.layer), args.yaw)
    except (AssetError, ValueError) as exc:
        print(f"error: {exc}")
        return 2
    if sun is None:
        print(f"{args.file}: no sun (nothing {SUN_CONTRAST:g} times brighter than the median of the sky)")
        return 1

    def numbers(values: tuple[float, ...]) -> str:
        return "[" + ", ".join(f"{v:.6g}" for v in values) + "]"

    print(f"DirectionalLight = {{ direction = {numbers(sun.direction)}, color = {numbers(sun.color)}, "
          f"intensity = {sun.intensity * args.intensity:.6g}, angular_diameter = {sun.angular_diameter:.4g} }}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
