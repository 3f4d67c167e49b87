"""Image data for textures, kept on the CPU; the renderer uploads it when first drawn."""
from __future__ import annotations

import errno
import math
import numbers
import os
import stat
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from engine.core.errors import AssetError

if TYPE_CHECKING:  # Pillow is imported when an image is first decoded (pillow_image_module)
    from types import ModuleType

    import PIL.Image


@dataclass(eq=False)
class TextureData:
    """RGBA pixels, row 0 at the top (as image files store them): sRGB encoded colour for
    ``Material.texture``, linear data for ``Material.normal_map`` (the renderer reads each as
    its field says).  Eight bits a channel, or sixteen (uint16) where the finer steps matter
    and the upload keeps them: a normal map (uploaded as normalised 16-bit, RGBA16; a colour
    texture is rounded to 8 bits at upload, sRGB has no 16-bit format).  ``load_texture``
    scales every other file format to 8 bits."""

    ASSET_KIND = "texture"  # what Material.texture and normal_map check for (components do not import the engine)

    pixels: np.ndarray
    name: str = "texture"
    source: dict | None = None  # how it was made, as a level file writes it (None: from arrays)

    def __post_init__(self) -> None:
        p = np.asarray(self.pixels)
        if p.ndim != 3 or p.shape[2] not in (3, 4) or p.shape[0] < 1 or p.shape[1] < 1:
            raise AssetError(f"texture {self.name!r}: pixels must be HxWx3 or HxWx4, got shape {p.shape}")
        if p.dtype not in (np.uint8, np.uint16):
            raise AssetError(f"texture {self.name!r}: pixels must be uint8 (or uint16: a normal map's finer "
                             f"slopes), got {p.dtype}")
        if p.shape[2] == 3:
            p = np.concatenate([p, np.full(p.shape[:2] + (1,), np.iinfo(p.dtype).max, p.dtype)], axis=2)
        self.pixels = np.ascontiguousarray(p)

    @property
    def size(self) -> tuple[int, int]:
        return self.pixels.shape[1], self.pixels.shape[0]

    @property
    def has_alpha(self) -> bool:
        return bool((self.pixels[..., 3] < np.iinfo(self.pixels.dtype).max).any())

    def as_8_bits(self) -> np.ndarray:
        """The pixels as uint8 (16-bit channels rounded: ``round(v * 255 / 65535)``)."""
        if self.pixels.dtype == np.uint8:
            return self.pixels
        return ((self.pixels.astype(np.uint32) * 255 + 32767) // 65535).astype(np.uint8)


MAX_TEXTURE_SIDE = 16384  # texels along a side of a texture the engine makes or loads (see below)
MAX_GENERATED_SIZE = MAX_TEXTURE_SIDE  # the generators' size limit (the older name)
MAX_IMAGE_FILE_BYTES = 1 << 30  # an image file's size on disk (the budget: no file past it decodes within it)
ASSET_MEMORY_BUDGET = 1 << 30  # bytes one texture's pixels (or one mesh's arrays) may take on the CPU
WORK_BLOCK = 1 << 16  # texels a generator or a conversion works on at a time (its float temporaries)
# MAX_TEXTURE_SIDE is the GL_MAX_TEXTURE_SIZE every OpenGL 4.1 context has at least: a texture
# past it is refused when made or loaded, before any pixel is decoded or allocated (the renderer
# checks its own context's limit again at upload). 16384 x 16384 RGBA8 is 1 GiB, exactly the
# budget: a generator allocates about what it returns (plus WORK_BLOCK texels of temporaries),
# and a decoded image about its size in its own format on top of that.


def check_texture_size(width: int, height: int, what: str, texel_bytes: int = 4) -> None:
    """Refuse a ``width`` x ``height`` texture past the GL side limit or the memory budget,
    before anything is allocated (``what`` names it in the message); ``texel_bytes``: 4
    (RGBA8) or 8 (RGBA16: a 16-bit normal map, or one made from a bump map)."""
    if not (1 <= width <= MAX_TEXTURE_SIDE and 1 <= height <= MAX_TEXTURE_SIDE):
        raise AssetError(f"{what}: is {width}x{height} texels: a texture is at most "
                         f"{MAX_TEXTURE_SIDE}x{MAX_TEXTURE_SIDE} (the GL_MAX_TEXTURE_SIZE OpenGL 4.1 guarantees)")
    size = texture_bytes(width, height, texel_bytes)
    if size > ASSET_MEMORY_BUDGET:
        raise AssetError(f"{what}: {width}x{height} texels take {_mib(size)} MiB, over the memory budget of "
                         f"{_mib(ASSET_MEMORY_BUDGET)} MiB an asset may have "
                         "(engine.assets.texture_data.ASSET_MEMORY_BUDGET)")


def colour_image(image: np.ndarray, who: str) -> np.ndarray:
    """``image`` as float64 linear colours to write to a file, checked: (height, width, 3), 1
    to ``MAX_TEXTURE_SIDE`` a side, finite; a ValueError starting with ``who`` otherwise."""
    pixels = np.asarray(image, np.float64)
    if pixels.ndim != 3 or pixels.shape[2] != 3 or not (1 <= pixels.shape[0] <= MAX_TEXTURE_SIDE) \
            or not (1 <= pixels.shape[1] <= MAX_TEXTURE_SIDE):
        raise ValueError(f"{who}: an (height, width, 3) image of 1 to {MAX_TEXTURE_SIDE} a side, got shape "
                         f"{pixels.shape}")
    if not np.isfinite(pixels).all():
        raise ValueError(f"{who}: colours must be finite")
    return pixels


def texture_bytes(width: int, height: int, texel_bytes: int = 4) -> int:
    """Bytes of a ``width`` x ``height`` TextureData (RGBA8; ``texel_bytes`` 8: RGBA16)."""
    return int(width) * int(height) * int(texel_bytes)


def _mib(size: int) -> str:
    return f"{size / (1 << 20):.0f}" if size >= 1 << 20 else f"{size / (1 << 20):.2f}"


# --- files ---------------------------------------------------------------------------------------

_FILE_KINDS = ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO"), (stat.S_ISCHR, "a character device"),
               (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"))


def check_asset_file(path: str | Path, what: str, max_bytes: int | None = None) -> os.stat_result:
    """Check, before any loader opens it, that ``path`` is a regular file this process may
    read (and at most ``max_bytes`` long); an AssetError starting with ``what`` says what it
    is instead (``file_problem``). Returns its stat."""
    problem, info = file_problem(path, max_bytes)
    if problem is not None:
        raise AssetError(f"{what}: {problem}")
    return info


def file_problem(path: str | Path, max_bytes: int | None = None) -> tuple[str | None, os.stat_result | None]:
    """(None, stat) when ``path`` is a regular file this process may read (at most
    ``max_bytes`` long), else (why not, None): no such file, a symlink loop, a directory, a
    FIFO, a device, permission denied, too large. The file is stat-ed, then opened without
    blocking (O_NONBLOCK: a FIFO put in its place meanwhile is seen, not waited on) and
    closed again; nothing is read."""
    def reason(exc: OSError) -> str:
        if exc.errno in (errno.ENOENT, errno.ENOTDIR):
            return "no such file"
        if exc.errno == errno.ELOOP:
            return "is a symlink loop (or too many links)"
        if exc.errno in (errno.EACCES, errno.EPERM):
            return "cannot be read (permission denied)"
        return f"cannot be read ({exc.strerror or exc})"

    try:
        info = os.stat(path)
    except OSError as exc:
        return reason(exc), None
    except ValueError as exc:  # a NUL in the path
        return f"is not a usable path ({exc})", None
    if not stat.S_ISREG(info.st_mode):
        return _not_regular(info), None
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0))
    except OSError as exc:
        return reason(exc), None
    try:
        info = os.fstat(fd)  # what was opened: a FIFO swapped in after the stat is seen here
    finally:
        os.close(fd)
    if not stat.S_ISREG(info.st_mode):
        return _not_regular(info), None
    if max_bytes is not None and info.st_size > max_bytes:
        return f"is {info.st_size} bytes, more than the {max_bytes} such a file may be", None
    return None, info


def read_asset_file(path: str | Path, what: str, max_bytes: int) -> bytes:
    """The bytes of ``path`` after ``file_problem``'s checks, made again on the descriptor
    that is read (opened without blocking: a FIFO swapped in after the check is refused, not
    waited on), at most ``max_bytes`` of them; an AssetError starting with ``what`` otherwise."""
    check_asset_file(path, what, max_bytes)
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0))
    except OSError as exc:
        raise AssetError(f"{what}: cannot be read ({exc.strerror or exc})") from None
    with os.fdopen(fd, "rb") as file:
        info = os.fstat(file.fileno())
        if not stat.S_ISREG(info.st_mode):
            raise AssetError(f"{what}: {_not_regular(info)}")
        if info.st_size > max_bytes:
            raise AssetError(f"{what}: is {info.st_size} bytes, more than the {max_bytes} such a file may be")
        data = file.read(min(info.st_size, max_bytes) + 1)  # read(n) allocates n bytes first
    if len(data) > max_bytes:
        raise AssetError(f"{what}: is more than the {max_bytes} bytes such a file may be")
    return data


def _not_regular(info: os.stat_result) -> str:
    kind = next((name for test, name in _FILE_KINDS if test(info.st_mode)), "not a file")
    return f"is {kind}, not a regular file"


def contained_path(path: str | Path, roots: Sequence[str | Path]) -> Path | None:
    """``path`` absolute with its links followed when it is inside one of ``roots`` (folders),
    both as written and once its links are followed; None when it is not. Nothing is
    opened and no error is raised, so the answer says nothing about whether an outside
    file exists."""
    def inside(candidate: Path, folders: list[Path]) -> bool:
        return any(candidate == folder or folder in candidate.parents for folder in folders)

    written, real = Path(os.path.abspath(path)), Path(os.path.realpath(path))
    real_roots = [Path(os.path.realpath(root)) for root in roots]
    if not inside(written, [Path(os.path.abspath(root)) for root in roots] + real_roots):
        return None
    return real if inside(real, real_roots) else None


def pillow_image_module() -> ModuleType:
    """PIL.Image with its decompression-bomb limit set from the GL texture limit
    (``MAX_TEXTURE_SIDE`` squared) instead of Pillow's default: every image the engine
    decodes (texture files, and a mesh file's images through trimesh) is held to it."""
    from PIL import Image

    Image.MAX_IMAGE_PIXELS = MAX_TEXTURE_SIDE * MAX_TEXTURE_SIDE
    return Image


def load_texture(path: str | Path, keep_16_bits: bool = False) -> TextureData:
    """Read an image file (PNG, JPEG, TIFF, ...) with Pillow as RGBA8, row 0 at the top.

    Its size is checked from the header (``check_texture_size``) before any pixel is
    decoded. Pixel formats are scaled to 8 bits, not clipped: 16-bit channels as ``round(v *
    255 / 65535)`` (Pillow itself takes a 16-bit RGB or RGBA PNG's high byte, within one step
    of that), floating-point (mode F) as ``round(clip(v, 0, 1) * 255)`` (NaN is refused); 32-bit
    integer images have no agreed range and are refused. What is kept is 8 bits a channel:
    TextureData is what the renderer uploads, RGBA8, so a 16-bit normal map is rounded to 8
    bits (the terraces the Material docstring notes), unless ``keep_16_bits`` (a normal map,
    as level files load one): a 16-bit PNG is then decoded whole (pypng: Pillow reads a 16-bit
    RGB PNG as 8 bits) into uint16 pixels. Values are not converted between linear and sRGB:
    a file's 0.5 is 128, read as its Material field says."""
    if isinstance(path, bytes) or not isinstance(path, (str, os.PathLike)):
        raise AssetError(f"texture file path must be a str or pathlib.Path, got {type(path).__name__} {path!r}")
    path = Path(path)
    what = f"texture file {str(path)!r}"
    check_asset_file(path, what, MAX_IMAGE_FILE_BYTES)
    if keep_16_bits and _png_bit_depth(path) == 16:
        return TextureData(_read_png_16(path, what), name=path.name, source={"file": str(path.resolve())})
    Image = pillow_image_module()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", Image.DecompressionBombWarning)
            with Image.open(path) as image:
                check_texture_size(*image.size, what)
                pixels = image_to_rgba8(image, what)
    except AssetError:
        raise
    except MemoryError:
        raise AssetError(f"{what}: does not fit in memory") from None
    except (Image.DecompressionBombError, Image.DecompressionBombWarning):
        raise AssetError(f"{what}: declares more pixels than a texture may have ({MAX_TEXTURE_SIDE}x"
                         f"{MAX_TEXTURE_SIDE}, the GL_MAX_TEXTURE_SIZE OpenGL 4.1 guarantees)") from None
    except Exception as exc:  # noqa: BLE001 - Pillow raises many kinds for a corrupt file
        raise AssetError(f"{what}: cannot be read as an image ({type(exc).__name__}: {exc})") from None
    return TextureData(pixels, name=path.name, source={"file": str(path.resolve())})


def _png_bit_depth(path: Path) -> int | None:
    """A PNG's bit depth from its header (IHDR), or None for any other file."""
    with open(path, "rb") as file:
        head = file.read(26)
    if len(head) < 26 or head[:8] != b"\x89PNG\r\n\x1a\n" or head[12:16] != b"IHDR":
        return None
    return head[24]


def _read_png_16(path: Path, what: str) -> np.ndarray:
    """A 16-bit PNG as HxWx3 or HxWx4 uint16 (greyscale as three equal channels), its size
    checked from the header before a row is decoded."""
    import png

    try:
        with open(path, "rb") as file:  # closed however the read ends (pypng's own open is not)
            width, height, rows, info = png.Reader(file=file).asDirect()
            check_texture_size(width, height, what, 8)  # kept as RGBA16
            planes = info["planes"]
            pixels = np.vstack([np.asarray(row, np.uint16) for row in rows]).reshape(height, width, planes)
    except AssetError:
        raise
    except MemoryError:
        raise AssetError(f"{what}: does not fit in memory") from None
    except Exception as exc:  # noqa: BLE001 - pypng raises its own kinds for a corrupt file
        raise AssetError(f"{what}: cannot be read as a 16-bit PNG ({type(exc).__name__}: {exc})") from None
    if planes in (1, 2):  # grey, grey + alpha
        grey = pixels[..., :1]
        pixels = np.concatenate([grey, grey, grey] + ([pixels[..., 1:2]] if planes == 2 else []), axis=2)
    return np.ascontiguousarray(pixels)


def image_to_rgba8(image: PIL.Image.Image, what: str) -> np.ndarray:
    """A Pillow image as an HxWx4 uint8 array, every pixel format scaled to 0..255 (see
    ``load_texture``); ``what`` names the image in an error."""
    mode = image.mode
    if mode.startswith("I;16") or (mode == "I" and image.format == "PNG"):  # a 16-bit PNG in older Pillows
        return _grey_to_rgba(np.asarray(image), lambda v: (np.clip(v, 0, 65535).astype(np.uint32) * 255 + 32767)
                             // 65535, what)
    if mode == "I":
        raise AssetError(f"{what}: has 32-bit integer pixels, which have no agreed range: save it with 8 or 16 bits "
                         "a channel, or as floating point in [0, 1]")
    if mode == "F":
        return _grey_to_rgba(np.asarray(image), lambda v: np.rint(np.clip(v, 0.0, 1.0) * 255.0), what)
    return np.asarray(image.convert("RGBA"))


def _grey_to_rgba(grey: np.ndarray, scale, what: str) -> np.ndarray:
    """One channel of any number kind to opaque grey RGBA8, ``scale`` applied a block of rows
    at a time (its temporaries stay small)."""
    height, width = grey.shape[:2]
    out = np.empty((height, width, 4), np.uint8)
    out[..., 3] = 255
    rows = max(1, WORK_BLOCK // max(1, width))
    for top in range(0, height, rows):
        block = grey[top:top + rows]
        if block.dtype.kind == "f" and np.isnan(block).any():
            raise AssetError(f"{what}: has NaN pixels")
        out[top:top + rows, :, :3] = np.asarray(scale(block), np.uint8)[..., np.newaxis]
    return out


# --- generators ----------------------------------------------------------------------------------

def checker_texture(size: int = 256, squares: int = 8, a: tuple[int, int, int] = (230, 230, 230),
                    b: tuple[int, int, int] = (40, 40, 48), name: str = "checker") -> TextureData:
    """A procedural checkerboard (the benchmark ground and the samples use it): ``size``
    texels square, ``squares`` cells a side (cells of ``size // squares`` texels), colour ``a``
    at the top-left cell, ``b`` on the others. Allocates the texture and two rows."""
    if not isinstance(name, str):
        raise AssetError(f"checker texture: name must be a string, got {name!r}")
    if isinstance(size, bool) or not isinstance(size, int) or not 1 <= size <= MAX_GENERATED_SIZE:
        raise AssetError(f"checker texture {name!r}: size must be an int in [1, {MAX_GENERATED_SIZE}], got {size!r}")
    if isinstance(squares, bool) or not isinstance(squares, int) or not 1 <= squares <= size:
        raise AssetError(f"checker texture {name!r}: squares must be an int in [1, size={size}], got {squares!r}")
    colours = {"a": _colour(a, "a", name), "b": _colour(b, "b", name)}
    check_texture_size(size, size, f"checker texture {name!r}")
    cell = max(1, size // squares)
    odd_columns = ((np.arange(size) // cell) % 2).astype(bool)[:, np.newaxis]
    first, second = (np.array(colours[k] + (255,), np.uint8) for k in ("a", "b"))
    rows = np.stack([np.where(odd_columns, second, first), np.where(odd_columns, first, second)])  # (2, size, 4)
    pixels = np.empty((size, size, 4), np.uint8)
    np.take(rows, (np.arange(size) // cell) % 2, axis=0, out=pixels, mode="clip")  # "raise" buffers a copy
    source = {"checker": [int(size), int(squares)],
              **({} if colours["a"] == (230, 230, 230) else {"a": list(colours["a"])}),
              **({} if colours["b"] == (40, 40, 48) else {"b": list(colours["b"])}),
              **({} if name == "checker" else {"name": name})}
    return TextureData(pixels, name=name, source=source)


def _colour(value, which: str, name: str) -> tuple[int, int, int]:
    if not isinstance(value, (tuple, list)) or len(value) != 3 or not all(
            isinstance(c, (int, np.integer)) and not isinstance(c, bool) and 0 <= c <= 255 for c in value):
        raise AssetError(f"checker texture {name!r}: {which} must be three integers in [0, 255], got {value!r}")
    return tuple(int(c) for c in value)


def puff_texture(size: int = 64, seed: int = 0, name: str = "puff") -> TextureData:
    """A soft white puff for particles (``ParticleEmitter.texture``: smoke, dust, steam): its
    alpha a round falloff, (1 - r^2)^2 as the untextured spot's, times a cloudy value noise
    (four octaves of a grid of random values, smoothly interpolated, each twice as fine and
    half as strong, from ``seed``), so each puff has lumps without a hard edge; white in
    colour (the emitter's colour tints it).  The same ``size`` and ``seed`` make the same
    pixels."""
    if isinstance(size, bool) or not isinstance(size, int) or not 4 <= size <= MAX_GENERATED_SIZE:
        raise AssetError(f"puff texture {name!r}: size must be an int in [4, {MAX_GENERATED_SIZE}], got {size!r}")
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed < 2**32:
        raise AssetError(f"puff texture {name!r}: seed must be an int in [0, 2^32), got {seed!r}")
    if not isinstance(name, str):
        raise AssetError(f"puff texture: name must be a string, got {name!r}")
    check_texture_size(size, size, f"puff texture {name!r}")
    rng = np.random.default_rng(seed)
    centres = (np.arange(size, dtype=np.float64) + 0.5) / size
    noise = np.zeros((size, size))
    for octave in range(4):
        cells = 4 << octave
        grid = rng.random((cells + 1, cells + 1))
        at = centres * cells
        i = np.minimum(at.astype(int), cells - 1)
        f = at - i
        f = f * f * (3.0 - 2.0 * f)  # smoothstep between the grid's values
        rows = grid[i][:, i] * (1 - f)[None, :] + grid[i][:, i + 1] * f[None, :]
        below = grid[i + 1][:, i] * (1 - f)[None, :] + grid[i + 1][:, i + 1] * f[None, :]
        noise += (rows * (1 - f)[:, None] + below * f[:, None]) * 0.5 ** octave
    noise /= sum(0.5 ** octave for octave in range(4))
    r2 = (centres[None, :] - 0.5) ** 2 * 4.0 + (centres[:, None] - 0.5) ** 2 * 4.0
    alpha = np.maximum(1.0 - r2, 0.0) ** 2 * np.clip(0.35 + 1.3 * noise, 0.0, 1.0)
    pixels = np.full((size, size, 4), 255, np.uint8)
    pixels[..., 3] = np.rint(alpha * 255.0).astype(np.uint8)
    source = {"puff": [int(size), int(seed)], **({} if name == "puff" else {"name": name})}
    return TextureData(pixels, name=name, source=source)


MAX_RIPPLE_SLOPE = 100.0  # the steepest ripple then leans 89.4 degrees: past it, all edge-on


def ripple_normal_map(size: int = 256, rings: int = 6, slope: float = 0.5, name: str = "ripples") -> TextureData:
    """A tangent-space normal map of concentric ripples about the texture's centre: a sample
    and test map for ``Material.normal_map`` whose every texel has a known normal.

    The height is ``h(r) = cos(2 pi rings r) / (2 pi rings)`` (``r``: distance from the
    centre ``(0.5, 0.5)`` in UV units), so ``|dh/dr| <= 1``: ``slope`` is the steepest
    gradient of the bumps (``slope = 1`` tilts the normal 45 degrees at the steepest,
    whatever ``rings`` and ``size``), and the centre is a smooth crest whose normal is +Z.
    Each texel holds, at its centre, ``n = normalize(-slope dh/du, -slope dh/dv, 1)`` from the
    analytic gradient (no finite differences), encoded the OpenGL way: RGB = ``n * 0.5 + 0.5``
    (red +U, green +V, blue out of the surface), alpha 255, read linearly. Row 0 is the top
    of the image (``v = 1 - (row + 0.5) / size``), so green grows upwards in the image.
    """
    if isinstance(size, bool) or not isinstance(size, int) or not 1 <= size <= MAX_GENERATED_SIZE:
        raise AssetError(f"ripples normal map {name!r}: size must be an int in [1, {MAX_GENERATED_SIZE}], "
                         f"got {size!r}")
    if isinstance(rings, bool) or not isinstance(rings, int) or not 1 <= rings <= size:
        raise AssetError(f"ripples normal map {name!r}: rings must be an int in [1, size={size}], got {rings!r}")
    if isinstance(slope, bool) or not isinstance(slope, numbers.Real) or not 0 <= slope <= MAX_RIPPLE_SLOPE:
        raise AssetError(f"ripples normal map {name!r}: slope must be a number in [0, {MAX_RIPPLE_SLOPE:g}], "
                         f"got {slope!r}")
    if not isinstance(name, str):
        raise AssetError(f"ripples normal map: name must be a string, got {name!r}")
    check_texture_size(size, size, f"ripples normal map {name!r}")
    centres = (np.arange(size, dtype=np.float64) + 0.5) / size
    du = centres[np.newaxis, :] - 0.5           # columns: u grows to the right
    dv = (1.0 - centres)[:, np.newaxis] - 0.5   # rows: row 0 is the top, v = 1 at the top edge
    pixels = np.full((size, size, 4), 255, np.uint8)
    block = max(1, WORK_BLOCK // size)          # rows at a time: the float work stays small at any size
    for top in range(0, size, block):
        rows = dv[top:top + block]
        r = np.hypot(du, rows)
        # -slope dh/du = -slope (dh/dr) (u - 0.5) / r, dh/dr = -sin(2 pi rings r), and
        # sin(2 pi k r) / r = 2 pi k sinc(2 k r): no 0/0 at the centre.
        tilt = float(slope) * 2.0 * math.pi * rings * np.sinc(2.0 * rings * r)
        n = np.stack([tilt * du, tilt * rows, np.ones_like(r)], axis=-1)
        n /= np.linalg.norm(n, axis=-1, keepdims=True)
        pixels[top:top + block, :, :3] = np.clip(np.rint(n * 127.5 + 127.5), 0, 255).astype(np.uint8)
    source = {"ripples": [int(size), int(rings)], **({} if float(slope) == 0.5 else {"slope": float(slope)}),
              **({} if name == "ripples" else {"name": name})}
    return TextureData(pixels, name=name, source=source)


MAX_WAVE_TRAINS = 64   # a wave normal map's trains at most (each a sum's term, every texel)


def wave_normal_map(size: int = 256, waves: int = 12, slope: float = 0.5, seed: int = 0,
                    name: str = "waves") -> TextureData:
    """A tileable tangent-space normal map of a wind-blown water surface: ``waves`` trains of
    sine waves summed (a sum of sines, the oldest ocean-surface model), their directions
    spread about +U, each a whole number of wavelengths across the tile along U and V (so it
    repeats seamlessly), from 2 to 2 + ``waves`` cycles a tile, each as high as its length
    (amplitude ~ 1 / frequency: every train as steep), their phases random from ``seed``.
    The sum is scaled so its steepest gradient over the texels is ``slope``.  Each texel
    holds, at its centre, ``n = normalize(-dh/du, -dh/dv, 1)`` from the sum's analytic
    gradient, encoded as ``ripple_normal_map``'s (red +U, green +V, row 0 the top).  Where
    the ripples' rings are a test pattern, this is water: under ``Water`` its two scrolling
    layers cross into a moving net, and the caustics it gathers are the net of a sunlit pool."""
    if isinstance(size, bool) or not isinstance(size, int) or not 1 <= size <= MAX_GENERATED_SIZE:
        raise AssetError(f"waves normal map {name!r}: size must be an int in [1, {MAX_GENERATED_SIZE}], got {size!r}")
    if isinstance(waves, bool) or not isinstance(waves, int) or not 1 <= waves <= MAX_WAVE_TRAINS:
        raise AssetError(f"waves normal map {name!r}: waves must be an int in [1, {MAX_WAVE_TRAINS}], got {waves!r}")
    if isinstance(slope, bool) or not isinstance(slope, numbers.Real) or not 0 <= slope <= MAX_RIPPLE_SLOPE:
        raise AssetError(f"waves normal map {name!r}: slope must be a number in [0, {MAX_RIPPLE_SLOPE:g}], "
                         f"got {slope!r}")
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise AssetError(f"waves normal map {name!r}: seed must be an int >= 0, got {seed!r}")
    if not isinstance(name, str):
        raise AssetError(f"waves normal map: name must be a string, got {name!r}")
    check_texture_size(size, size, f"waves normal map {name!r}")
    trains = wave_trains(waves, seed)
    centres = (np.arange(size, dtype=np.float64) + 0.5) / size
    u = centres[np.newaxis, :]                  # columns: u grows to the right
    v = (1.0 - centres)[:, np.newaxis]          # rows: row 0 is the top
    gradient = np.zeros((size, size, 2))
    block = max(1, WORK_BLOCK // size)          # rows at a time: the float work stays small at any size
    for top in range(0, size, block):
        rows = v[top:top + block]
        for m, n, amplitude, phase in trains:   # dh/du, dh/dv of amplitude sin(2 pi (m u + n v) + phase)
            wave = amplitude * 2.0 * math.pi * np.cos(2.0 * math.pi * (m * u + n * rows) + phase)
            gradient[top:top + block, :, 0] += m * wave
            gradient[top:top + block, :, 1] += n * wave
    steepest = float(np.sqrt((gradient ** 2).sum(axis=-1)).max())
    gradient *= float(slope) / steepest if steepest > 0.0 else 0.0
    n = np.concatenate([-gradient, np.ones((size, size, 1))], axis=-1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    pixels = np.full((size, size, 4), 255, np.uint8)
    pixels[..., :3] = np.clip(np.rint(n * 127.5 + 127.5), 0, 255).astype(np.uint8)
    source = {"waves": [int(size), int(waves)], **({} if float(slope) == 0.5 else {"slope": float(slope)}),
              **({} if seed == 0 else {"seed": int(seed)}), **({} if name == "waves" else {"name": name})}
    return TextureData(pixels, name=name, source=source)


def wave_trains(waves: int, seed: int) -> list[tuple[int, int, float, float]]:
    """The (m, n, amplitude, phase) of each of ``wave_normal_map``'s trains: cycles a tile
    along U and V (whole numbers, not both 0), the height's amplitude (1 / frequency) and its
    phase, from ``seed``; directions within 60 degrees of +U, as a wind's."""
    rng = np.random.default_rng(seed)
    trains = []
    for k in range(waves):
        frequency = 2.0 + k + rng.uniform(0.0, 1.0)
        angle = rng.uniform(-math.pi / 3.0, math.pi / 3.0)
        m, n = round(frequency * math.cos(angle)), round(frequency * math.sin(angle))
        if m == 0 and n == 0:
            m = 1
        trains.append((m, n, 1.0 / math.hypot(m, n), float(rng.uniform(0.0, 2.0 * math.pi))))
    return trains


def is_grey(texture: TextureData) -> bool:
    """Every texel's red, green and blue are equal: a height (bump) map, not a normal map."""
    p = texture.pixels
    return bool((p[..., 0] == p[..., 1]).all() and (p[..., 1] == p[..., 2]).all())


def height_to_normal_map(height: TextureData, name: str | None = None) -> TextureData:
    """A tangent-space normal map (``Material.normal_map``'s convention: RGB = n x 0.5 + 0.5,
    red towards +U, green towards +V, i.e. up the image) from a height map (a grey bump map,
    as an OBJ's ``bump`` / ``map_Bump`` names one): heights are the red channel in 0..1, and
    a step of 1 between neighbouring texels is a slope of 1, so ``n = normalize(-dh/du,
    -dh/dv, 1)`` with the slopes taken by central differences per texel, one-sided at the
    image's edges (a map that does not tile would otherwise get a cliff along them; one that
    does loses only its edge texels' exact slope). Strength is left to
    ``Material.normal_scale`` (an MTL's ``-bm``). Written as 16 bits a channel (a normal map
    keeps them: gentle slopes without 8-bit terraces); worked a block of rows at a time."""
    p = height.pixels
    check_texture_size(p.shape[1], p.shape[0], f"normal map made from {height.name!r}", 8)
    h = p[..., 0].astype(np.float32) / float(np.iinfo(p.dtype).max)
    rows, cols = h.shape
    out = np.empty((rows, cols, 4), np.uint16)
    out[..., 3] = 65535
    columns = np.arange(cols)
    left, right = np.maximum(columns - 1, 0), np.minimum(columns + 1, cols - 1)
    across = np.maximum(right - left, 1).astype(np.float32)  # 2 inside, 1 at an edge (0 slope: 1 texel wide)
    block = max(1, WORK_BLOCK // max(1, cols))
    for top in range(0, rows, block):
        index = np.arange(top, min(rows, top + block))
        here = h[index]
        du = (here[:, right] - here[:, left]) / across                      # columns: u grows to the right
        up, down = np.maximum(index - 1, 0), np.minimum(index + 1, rows - 1)
        dv = (h[up] - h[down]) / np.maximum(down - up, 1)[:, None]          # row 0 is the top: v grows upwards
        n = np.stack([-du, -dv, np.ones_like(du)], axis=-1)
        n /= np.linalg.norm(n, axis=-1, keepdims=True)
        out[index, :, :3] = np.clip(np.rint(n * 32767.5 + 32767.5), 0, 65535).astype(np.uint16)
    return TextureData(out, name=name or f"{height.name} (as normals)")
