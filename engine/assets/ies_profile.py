"""IES light profiles: how a real luminaire's light falls off with direction, measured by its
maker and published as an IES LM-63 file (the photometric files Unreal's and HDRP's IES
profiles, Blender's and every lighting designer's tools read).

``load_ies(path)`` reads the text: its header lines up to ``TILT=NONE`` (a tilt table,
``TILT=INCLUDE`` or a file, is refused, saying so), then the numbers: lamps, lumens a lamp,
the candela multiplier, the counts of vertical and horizontal angles, the photometric type
(1, type C, the one luminaires use: vertical angles from the nadir, 0 to 180 degrees,
horizontal ones about it; types A and B are refused), the units and sizes, the ballast
factor, a number for future use and the input watts, then the vertical angles, the
horizontal ones and the candela values, a row of vertical ones for each horizontal angle.
Its horizontal angles may cover a quarter (0 to 90), a half (0 to 180) or the whole turn
(0 to 360), or be one angle (0: the same all round); the rest is the symmetry the file
states.  Every mistake is an ``AssetError`` naming the file and what is wrong.

``ies_cookie(profile)`` turns it into the panorama an all-round ``PointLight`` wraps about
itself (``PointLight.cookie``, an equirectangular image: ``engine/render/spot_cookies.py``):
each texel the profile's candelas along its direction over the profile's peak, sRGB-encoded
(the cookie's decoding gives the share back in linear light).  The profile's nadir (vertical
angle 0) is the light's forward, its entity's -Z, where a spot aims: turn the light to hang
it (``look_rotation((0, -1, 0))`` for a lamp shining down); horizontal angle 0 is towards its
+X and 90 towards its +Y.  The light's ``intensity`` is then its intensity along the peak
(``IesProfile.peak`` candelas in the file).
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from engine.assets.texture_data import TextureData, read_asset_file
from engine.core.color import linear_to_srgb
from engine.core.errors import AssetError

MAX_IES_FILE_BYTES = 4 << 20   # a profile is a few kilobytes; a megabyte is thousands of angles
MAX_IES_ANGLES = 4096          # vertical or horizontal angles a file may hold
COOKIE_WIDTH, COOKIE_HEIGHT = 256, 128   # the panorama ies_cookie makes: a texel ~1.4 degrees


@dataclass(eq=False)
class IesProfile:
    """A luminaire's candelas by direction: ``candela[h, v]`` at horizontal angle
    ``horizontal[h]`` and vertical angle ``vertical[v]`` (degrees, type C: 0 the nadir),
    the multiplier applied; ``peak`` the largest."""

    vertical: np.ndarray
    horizontal: np.ndarray
    candela: np.ndarray
    name: str = "ies"
    source: dict = field(default_factory=dict)

    @property
    def peak(self) -> float:
        return float(self.candela.max())

    def intensity(self, gamma: np.ndarray, phi: np.ndarray) -> np.ndarray:
        """Candelas along vertical angle ``gamma`` and horizontal angle ``phi`` (degrees, any
        shape alike), linear between the file's angles, the horizontal ones unfolded by the
        symmetry the file states; 0 past its last vertical angle."""
        gamma = np.asarray(gamma, np.float64)
        phi = np.mod(np.asarray(phi, np.float64), 360.0)
        last = float(self.horizontal[-1])
        if last == 0.0:   # the same all round
            phi = np.zeros_like(phi)
        elif last == 90.0:   # a quarter: mirrored about 0-180 and 90-270
            phi = np.where(phi > 180.0, 360.0 - phi, phi)
            phi = np.where(phi > 90.0, 180.0 - phi, phi)
        elif last == 180.0:   # a half: mirrored about 0-180
            phi = np.where(phi > 180.0, 360.0 - phi, phi)
        rows = np.stack([np.interp(gamma, self.vertical, row, right=0.0) for row in self.candela])
        if len(self.horizontal) == 1:
            return rows[0]
        h = np.interp(phi, self.horizontal, np.arange(len(self.horizontal), dtype=np.float64))
        low = np.floor(h).astype(int)
        high = np.minimum(low + 1, len(self.horizontal) - 1)
        f = h - low
        flat = rows.reshape(len(self.horizontal), -1)
        index = np.arange(flat.shape[1])
        return (flat[low.ravel(), index] * (1.0 - f.ravel()) + flat[high.ravel(), index] * f.ravel()).reshape(
            gamma.shape)


def parse_ies(text: str, name: str = "ies") -> IesProfile:
    """An ``IesProfile`` from an LM-63 file's ``text`` (``name``: the file, for the errors)."""
    def fail(why: str) -> AssetError:
        return AssetError(f"IES profile {name!r}: {why}")

    lines = text.splitlines()
    tilt = next((i for i, line in enumerate(lines) if line.strip().upper().startswith("TILT")), None)
    if tilt is None:
        raise fail("no TILT= line (an IES LM-63 file's header ends with one)")
    setting = lines[tilt].split("=", 1)[1].strip().upper() if "=" in lines[tilt] else ""
    if setting != "NONE":
        raise fail(f"TILT={setting or '?'}: only TILT=NONE is read (a tilt table changes the candelas with the "
                   "lamp's angle, which a fixed profile cannot hold)")
    numbers = []
    for token in re.split(r"[\s,]+", " ".join(lines[tilt + 1:]).strip()):
        if not token:
            continue
        try:
            value = float(token)
        except ValueError:
            raise fail(f"{token!r} is not a number (after TILT=NONE the file is numbers)") from None
        if not math.isfinite(value):
            raise fail(f"{token!r} is not a finite number")
        numbers.append(value)
    if len(numbers) < 13:
        raise fail(f"{len(numbers)} numbers after TILT=NONE; the counts, sizes and factors alone are 13")
    multiplier, n_vertical, n_horizontal, kind = numbers[2], numbers[3], numbers[4], numbers[5]
    for what, count in (("vertical", n_vertical), ("horizontal", n_horizontal)):
        if count != int(count) or not 1 <= count <= MAX_IES_ANGLES:
            raise fail(f"{count:g} {what} angles: a whole number from 1 to {MAX_IES_ANGLES}")
    n_vertical, n_horizontal = int(n_vertical), int(n_horizontal)
    if kind != 1.0:
        raise fail(f"photometric type {kind:g}: only type C (1), the luminaires' kind, is read (types A and B "
                   "measure about another axis)")
    if not multiplier > 0.0:
        raise fail(f"candela multiplier {multiplier:g}: must be above 0")
    body = numbers[13:]
    need = n_vertical + n_horizontal + n_vertical * n_horizontal
    if len(body) != need:
        raise fail(f"{len(body)} angles and candelas after the header; {n_vertical} vertical and "
                   f"{n_horizontal} horizontal angles and {n_vertical} x {n_horizontal} candelas are {need}")
    vertical = np.array(body[:n_vertical])
    horizontal = np.array(body[n_vertical:n_vertical + n_horizontal])
    candela = np.array(body[n_vertical + n_horizontal:]).reshape(n_horizontal, n_vertical) * multiplier
    if np.any(np.diff(vertical) <= 0.0) or vertical[0] < 0.0 or vertical[-1] > 180.0:
        raise fail("the vertical angles must rise from 0 or more to 180 at most (type C: 0 the nadir)")
    if vertical[0] != 0.0 and vertical[0] != 90.0:
        raise fail(f"the vertical angles start at {vertical[0]:g}: type C starts at 0 (or 90 for a light "
                   "shining up only)")
    if np.any(np.diff(horizontal) <= 0.0) or horizontal[0] != 0.0 or horizontal[-1] not in (0.0, 90.0, 180.0,
                                                                                               360.0):
        raise fail("the horizontal angles must rise from 0 to 0, 90, 180 or 360 (the symmetry the file states)")
    if np.any(candela < 0.0):
        raise fail("a candela value is negative")
    if not candela.max() > 0.0:
        raise fail("every candela value is 0: the light shines nowhere")
    if vertical[0] == 90.0:   # (shining up only: nothing below the horizon)
        vertical = np.concatenate([[0.0, 90.0 - 1e-6], vertical])
        candela = np.concatenate([np.zeros((n_horizontal, 2)), candela], axis=1)
    return IesProfile(vertical, horizontal, candela, name)


def load_ies(path: str | Path) -> IesProfile:
    """The profile in the IES file at ``path`` (``parse_ies``)."""
    path = Path(path)
    data = read_asset_file(path, f"IES profile {str(path)!r}", MAX_IES_FILE_BYTES)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        text = data.decode("latin-1")   # (older files' headers use Latin-1 for degree signs and names)
    profile = parse_ies(text, str(path))
    profile.source = {"ies": str(path)}
    return profile


def ies_cookie(profile: IesProfile, width: int = COOKIE_WIDTH, height: int = COOKIE_HEIGHT) -> TextureData:
    """``profile`` as the panorama an all-round ``PointLight.cookie`` wraps about its light
    (rows from the top, longitude across: the middle column ahead, the light's -Z; top row
    straight up, +Y): each texel's share of the peak along its direction, sRGB-encoded."""
    v = 1.0 - (np.arange(height) + 0.5) / height          # row 0 at the top
    u = (np.arange(width) + 0.5) / width
    lat = (v[:, None] - 0.5) * math.pi
    lon = (u[None, :] - 0.5) * 2.0 * math.pi
    x = np.cos(lat) * np.sin(lon)      # along the light's +X (its right)
    y = np.sin(lat) * np.ones_like(lon)   # along +Y
    z = np.cos(lat) * np.cos(lon)      # along its forward, -Z: the profile's nadir
    gamma = np.degrees(np.arccos(np.clip(z, -1.0, 1.0)))
    phi = np.degrees(np.arctan2(y, x))
    share = profile.intensity(gamma, phi) / profile.peak
    pixels = np.empty((height, width, 4), np.uint8)
    pixels[..., :3] = np.round(linear_to_srgb(np.clip(share, 0.0, 1.0)) * 255.0).astype(np.uint8)[..., None]
    pixels[..., 3] = 255
    texture = TextureData(pixels, name=profile.name)
    texture.source = dict(profile.source) if profile.source else None
    return texture
