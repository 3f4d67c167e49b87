"""OpenEXR images: HDR panoramas as most HDRI sites, renderers and compositors hand them out
(Poly Haven's are DWAA-compressed EXRs), read as linear Rec. 709 colours, and linear colours
written back as EXR for other tools (three.js's ``EXRLoader`` and ``EXRExporter``, Godot's and
Unity's EXR import).

Decoding goes through the Academy Software Foundation's own library (the ``openexr``
package, its Python binding): every compression the format has (none, RLE, ZIP, PIZ, PXR24,
B44, DWAA/DWAB, HTJ2K), half, float and uint channels, scanline and tiled files, several
parts.  What this module adds is the engine's side:

- which colours: the first part holding ``R``, ``G`` and ``B`` (``layer="name"``: the part of
  that name, or the channels ``name.R``, ``name.G``, ``name.B``), or a luminance-only ``Y``
  image as grey; alpha and other channels are left out;
- where: the display window is the image, the data window's pixels placed in it, the rest
  black (the format's rule);
- which primaries: a ``chromaticities`` attribute other than Rec. 709's (ACES2065-1's AP0, a
  camera's, Rec. 2020) is converted to the engine's Rec. 709 with Bradford's adaptation to D65,
  as OpenColorIO does; colours that fall outside Rec. 709 (negative) are clipped to 0;
- what the sky can hold: a non-finite colour, or one past 65504 (a sky face's half float), is
  refused, as the ``.hdr`` reader refuses it;
- which map: a file whose ``envmap`` attribute says cube holds a cube map's six faces stacked,
  one whose attribute says latlong an equirectangular panorama in OpenEXR's own wrap (its middle
  column +Z), one without the attribute an image (``load_exr_environment``;
  ``engine/assets/panorama.py`` makes each a panorama in the engine's wrap).
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from components.tracking import HALF_MAX
from engine.assets.texture_data import check_asset_file, colour_image
from engine.core.color import REC709_CHROMATICITIES, to_rec709_matrix
from engine.core.errors import AssetError

MAX_EXR_FILE_BYTES = 1 << 30       # as a panorama file (engine/assets/panorama.py)
MAX_EXR_PIXELS = 8192 * 4096       # an 8K HDRI: checked from the header, before any pixel is decoded
_MAGIC = b"\x76\x2f\x31\x01"       # every OpenEXR file's first four bytes
COMPRESSIONS = ("none", "rle", "zips", "zip", "piz", "pxr24", "b44", "b44a", "dwaa", "dwab")


def _library(what: str):
    try:
        import OpenEXR
    except ImportError as exc:  # a dependency of the engine; a broken install says so here
        raise AssetError(f"{what}: reading and writing OpenEXR files needs the 'openexr' package "
                         f"(pip install openexr): {exc}") from exc
    return OpenEXR


def load_exr(path: str | Path, layer: str | None = None) -> np.ndarray:
    """An OpenEXR file's colours, (height, width, 3) float32 linear Rec. 709, row 0 at the top
    of its display window: the first part with R, G and B (or Y alone, as grey), or ``layer``'s
    (a part's name, or a channel prefix ``layer.``); see the module's docstring.  A cube-map
    environment's six faces stacked as the file holds them (``load_exr_environment`` says
    which it is)."""
    return load_exr_environment(path, layer)[0]


def load_exr_environment(path: str | Path, layer: str | None = None) -> tuple[np.ndarray, str]:
    """``load_exr``'s colours and the file's environment map kind, as its ``envmap`` attribute
    says: "cube", a cube map's six faces (N x 6N pixels: +X, -X, +Y, -Y, +Z, -Z from the top,
    each as OpenEXR's ``ImfEnvmap.h`` lays it out; one of another shape is refused);
    "latlong", an equirectangular panorama as ``ImfEnvmap.h`` wraps it (longitude +pi at the
    left edge to -pi at the right, 0 at the middle column pointing +Z, +pi/2 +X); "image"
    where the file has no ``envmap`` attribute (a plain picture: an HDRI site's panorama, taken
    in the engine's own wrap as an ``.hdr`` file is)."""
    if isinstance(path, bytes) or not isinstance(path, (str, os.PathLike)):
        raise AssetError(f"OpenEXR file path must be a str or pathlib.Path, got {type(path).__name__} {path!r}")
    if layer is not None and (not isinstance(layer, str) or not layer):
        raise AssetError(f"OpenEXR layer must be a non-empty str or None, got {layer!r}")
    path = Path(path)
    what = f"OpenEXR file {str(path)!r}"
    check_asset_file(path, what, MAX_EXR_FILE_BYTES)
    with open(path, "rb") as stream:
        if stream.read(4) != _MAGIC:
            raise AssetError(f"{what}: not an OpenEXR file (it does not start with the bytes 76 2f 31 01)")
    openexr = _library(what)
    try:
        return _load(openexr, path, layer, what)
    except (UnicodeDecodeError, TypeError, KeyError, AttributeError, IndexError) as exc:  # the binding's
        # attributes as a corrupt header leaves them (names that are not text, values of other types)
        raise AssetError(f"{what}: its header is corrupt ({type(exc).__name__}: {exc})") from exc


def _load(openexr: Any, path: Path, layer: str | None, what: str) -> tuple[np.ndarray, str]:
    headers = _read(openexr, path, what, header_only=True)
    part_index, prefix = _choose_part(headers, layer, what)
    header = headers.parts[part_index].header
    display, data_window = _windows(header, what)
    envmap = header.get("envmap")
    kind = "image" if envmap is None else "cube" if str(envmap).endswith("CUBE") else "latlong"
    width, height = display[2] - display[0] + 1, display[3] - display[1] + 1
    if kind == "cube" and height != 6 * width:
        raise AssetError(f"{what}: is a cube-map environment (envmap = cube) of {width} x {height} pixels; its six "
                         f"faces stacked are N x 6N ({width} x {6 * width} here)")
    names = _colour_names(header["channels"], prefix)
    pixels = _read(openexr, path, what, header_only=False).parts[part_index].channels
    planes = []
    for name in names:
        channel = pixels[name]
        if channel.xSampling != 1 or channel.ySampling != 1:
            raise AssetError(f"{what}: channel {name!r} is subsampled ({channel.xSampling} x {channel.ySampling}); "
                             "a luminance-chroma (Y, RY, BY) image is not read: save it as R, G, B")
        planes.append(np.asarray(channel.pixels, np.float32))
    colours = np.stack(planes if len(planes) == 3 else planes * 3, axis=-1)
    bad = ~np.isfinite(colours)
    if bad.any():
        raise AssetError(f"{what}: {int(bad.any(axis=-1).sum())} pixels hold NaN or infinite colours")
    primaries = _primaries(header, what)
    if primaries is not None and len(names) == 3 and not np.allclose(primaries, REC709_CHROMATICITIES, atol=1e-4):
        colours = colours @ to_rec709_matrix(primaries).T.astype(np.float32)
    colours = np.maximum(colours, np.float32(0.0))
    if colours.max(initial=0.0) > HALF_MAX:
        raise AssetError(f"{what}: holds colours past {HALF_MAX:g} (up to {colours.max():g}), more than the "
                         "half floats a sky's faces keep")
    return _placed(colours, display, data_window), kind


def _primaries(header: dict, what: str) -> tuple[float, ...] | None:
    """The ``chromaticities`` attribute as 8 numbers, or None without one; refused when it is
    not a set of primaries a matrix can be made from."""
    given = header.get("chromaticities")
    if given is None:
        return None
    try:
        primaries = tuple(float(c) for c in given)
        matrix = to_rec709_matrix(primaries) if len(primaries) == 8 else None
    except (TypeError, ValueError, ZeroDivisionError, np.linalg.LinAlgError):
        matrix = None
    if matrix is None or not np.isfinite(matrix).all():
        raise AssetError(f"{what}: its chromaticities attribute is not red, green, blue and white "
                         "x, y pairs a colour conversion can be made from")
    return primaries


def _read(openexr: Any, path: Path, what: str, header_only: bool) -> Any:
    try:
        exr = openexr.File(str(path), separate_channels=True, header_only=header_only)
    except (RuntimeError, ValueError, OSError) as exc:
        raise AssetError(f"{what}: cannot be read as OpenEXR ({exc})") from exc
    if not exr.parts:
        raise AssetError(f"{what}: cannot be read as OpenEXR (no part could be read: truncated or corrupt)")
    return exr


def _choose_part(exr: Any, layer: str | None, what: str) -> tuple[int, str]:
    """(part index, channel prefix) of the colours to read."""
    found = []
    for index, part in enumerate(exr.parts):
        header = part.header
        kind = str(header.get("type", ""))
        names = [str(c.name) for c in header.get("channels", [])]
        found.append(f"{part.name() or index}: {', '.join(names) or 'no channels'}")
        if "deep" in kind:
            continue
        if layer is None:
            if {"R", "G", "B"} <= set(names) or "Y" in names:
                return index, ""
        elif part.name() == layer and ({"R", "G", "B"} <= set(names) or "Y" in names):
            return index, ""
        elif layer is not None and {f"{layer}.R", f"{layer}.G", f"{layer}.B"} <= set(names):
            return index, f"{layer}."
    wanted = f"layer {layer!r} (a part of that name, or channels {layer}.R, .G, .B)" if layer is not None \
        else "an image part with channels R, G and B (or Y)"
    raise AssetError(f"{what}: has no {wanted}; its parts: {'; '.join(found)}")


def _colour_names(channels: list[Any], prefix: str) -> list[str]:
    names = [str(channel.name) for channel in channels]
    if all(f"{prefix}{c}" in names for c in "RGB"):
        return [f"{prefix}{c}" for c in "RGB"]
    return [f"{prefix}Y"]


def _windows(header: dict, what: str) -> tuple[tuple[int, int, int, int], tuple[int, int, int, int]]:
    """The display and data windows as (x min, y min, x max, y max), checked for size."""
    windows = []
    for key in ("displayWindow", "dataWindow"):
        try:
            low, high = header[key]
            box = (int(low[0]), int(low[1]), int(high[0]), int(high[1]))
        except (KeyError, TypeError, ValueError, IndexError) as exc:
            raise AssetError(f"{what}: its {key} attribute is missing or not a box ({exc})") from exc
        width, height = box[2] - box[0] + 1, box[3] - box[1] + 1
        if width < 1 or height < 1:
            raise AssetError(f"{what}: its {key} is empty ({box})")
        if width * height > MAX_EXR_PIXELS:
            raise AssetError(f"{what}: its {key} is {width} x {height} pixels, more than the {MAX_EXR_PIXELS} "
                             f"(8192 x 4096) a panorama may have")
        windows.append(box)
    return windows[0], windows[1]


def _placed(colours: np.ndarray, display: tuple[int, int, int, int],
            data: tuple[int, int, int, int]) -> np.ndarray:
    """The data window's colours set in the display window, black where it has none."""
    width, height = display[2] - display[0] + 1, display[3] - display[1] + 1
    if data == display:
        return np.ascontiguousarray(colours, np.float32)
    image = np.zeros((height, width, 3), np.float32)
    x0, y0 = max(data[0], display[0]), max(data[1], display[1])
    x1, y1 = min(data[2], display[2]), min(data[3], display[3])
    if x0 <= x1 and y0 <= y1:
        image[y0 - display[1]:y1 - display[1] + 1, x0 - display[0]:x1 - display[0] + 1] = \
            colours[y0 - data[1]:y1 - data[1] + 1, x0 - data[0]:x1 - data[0] + 1]
    return image


def save_exr(path: str | Path, image: np.ndarray, half: bool = True, compression: str = "zip") -> Path:
    """Write linear Rec. 709 colours (height, width, 3; row 0 at the top; finite) as an OpenEXR
    file with channels R, G, B: half floats (``half=False``: 32-bit floats) in ``compression``
    (one of ``COMPRESSIONS``; ZIP is lossless and what most tools write), the Rec. 709
    chromaticities recorded, to bake a generated sky, a capture or a lightmap for other tools.
    Returns the path."""
    pixels = colour_image(image, "save_exr")
    if half and np.abs(pixels).max(initial=0.0) > HALF_MAX:
        raise ValueError(f"save_exr: colours past {HALF_MAX:g} do not fit half floats (up to "
                         f"{np.abs(pixels).max():g}): give half=False")
    if compression not in COMPRESSIONS:
        raise ValueError(f"save_exr: compression must be one of {', '.join(COMPRESSIONS)}, got {compression!r}")
    if not isinstance(half, bool):
        raise ValueError(f"save_exr: half must be True or False, got {half!r}")
    path = Path(path)
    openexr = _library(f"OpenEXR file {str(path)!r}")
    kind = np.float16 if half else np.float32
    channels = {c: np.ascontiguousarray(pixels[..., i], kind) for i, c in enumerate("RGB")}  # (the binding
    # writes a strided view's memory as if it were contiguous)
    header = {"compression": getattr(openexr, f"{'NO' if compression == 'none' else compression.upper()}_COMPRESSION"),
              "type": openexr.scanlineimage, "chromaticities": tuple(float(c) for c in REC709_CHROMATICITIES)}
    try:
        openexr.File(header, channels).write(str(path))
    except (RuntimeError, ValueError, OSError) as exc:
        raise AssetError(f"OpenEXR file {str(path)!r}: cannot be written ({exc})") from exc
    return path
