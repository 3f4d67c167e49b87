"""Colour lookup tables: a 3D grid that maps each colour of the finished picture to another,
as colourists grade in DaVinci Resolve or Photoshop and export as an Adobe/IRIDAS ``.cube``
file (the format Unity's, Unreal's and Godot's colour lookups and three.js's LUTPass read).

``load_cube_lut(path)`` reads the "Cube LUT Specification 1.0" text: ``LUT_3D_SIZE N``
(2 to ``MAX_LUT_SIZE``), optional ``TITLE``, ``DOMAIN_MIN`` and ``DOMAIN_MAX``, ``#``
comments, then N^3 lines of three numbers, red changing fastest.  A 1D table
(``LUT_1D_SIZE``) is refused, saying so.  Every mistake is an ``AssetError`` naming the file
and the line.  ``ColorLut`` holds the table on the CPU; the present pass uploads it as a
3D texture and looks each pixel's sRGB-encoded colour up in it (``ColorGrading.lut``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from engine.assets.texture_data import check_asset_file
from engine.core.errors import AssetError

MAX_LUT_SIZE = 129      # points a side (Resolve exports 17, 33 and 65; 129 is 6.4 MB as float16 RGBA)
MAX_LUT_FILE_BYTES = 128 << 20
HALF_MAX = 65504.0      # the table's texture holds half floats


@dataclass(eq=False)
class ColorLut:
    """A 3D colour table: ``table[b, g, r]`` is the output colour (RGB, float32) for the
    input (r, g, b) / (size - 1) of the domain, inputs between points interpolated
    trilinearly.  ``domain_min`` and ``domain_max`` are the input range the grid spans (the
    file's ``DOMAIN_MIN``/``DOMAIN_MAX``, 0 and 1 by default).  The table is its own copy,
    read-only: the GPU's copy is made once a table, so an edit in place would never reach the
    picture; it raises instead, at the edit (a changed table is a new ColorLut, given to
    ``ColorGrading.lut``)."""

    ASSET_KIND = "lut"  # what ColorGrading.lut checks for (components do not import the engine)

    table: np.ndarray
    name: str = "lut"
    domain_min: tuple[float, float, float] = (0.0, 0.0, 0.0)
    domain_max: tuple[float, float, float] = (1.0, 1.0, 1.0)
    source: dict | None = None  # how it was made, as a level file writes it (None: from arrays)

    def __post_init__(self) -> None:
        table = np.asarray(self.table)
        if table.ndim != 4 or table.shape[3] != 3 or not table.shape[0] == table.shape[1] == table.shape[2]:
            raise AssetError(f"colour table {self.name!r}: table must be N x N x N x 3, got shape {table.shape}")
        if not 2 <= table.shape[0] <= MAX_LUT_SIZE:
            raise AssetError(f"colour table {self.name!r}: {table.shape[0]} points a side; 2 to {MAX_LUT_SIZE} "
                             "are read")
        if not np.issubdtype(table.dtype, np.number) or not np.isfinite(table).all():
            raise AssetError(f"colour table {self.name!r}: every output must be a finite number")
        if np.abs(table).max() > HALF_MAX:
            raise AssetError(f"colour table {self.name!r}: an output of {np.abs(table).max():g} does not fit the "
                             f"half float it is drawn from (at most {HALF_MAX:g})")
        lo, hi = (tuple(float(v) for v in d) for d in (self.domain_min, self.domain_max))
        if len(lo) != 3 or len(hi) != 3 or not all(map(math.isfinite, lo + hi)) \
                or any(a >= b for a, b in zip(lo, hi, strict=True)):
            raise AssetError(f"colour table {self.name!r}: the domain must be finite with min < max a channel, "
                             f"got {lo} to {hi}")
        self.table = np.array(table, np.float32, order="C", copy=True)
        self.table.flags.writeable = False
        self.domain_min, self.domain_max = lo, hi

    @property
    def size(self) -> int:
        return self.table.shape[0]

    def apply(self, rgb: np.ndarray) -> np.ndarray:
        """The table applied to ``rgb`` (..., 3) on the CPU, trilinearly: what the present pass
        does on the GPU (tests compare the two)."""
        rgb = np.asarray(rgb, np.float64)
        lo, hi = np.array(self.domain_min), np.array(self.domain_max)
        at = np.clip((rgb - lo) / (hi - lo), 0.0, 1.0) * (self.size - 1)
        base = np.minimum(np.floor(at).astype(int), self.size - 2)
        f = at - base
        out = np.zeros(rgb.shape, np.float64)
        table = self.table.astype(np.float64)
        for corner in range(8):
            step = np.array([(corner >> 0) & 1, (corner >> 1) & 1, (corner >> 2) & 1])
            weight = np.prod(np.where(step == 1, f, 1.0 - f), axis=-1, keepdims=True)
            r, g, b = (base + step)[..., 0], (base + step)[..., 1], (base + step)[..., 2]
            out += weight * table[b, g, r]
        return out


def identity_lut(size: int = 33, name: str = "identity") -> ColorLut:
    """The table that changes nothing (each point its own colour): a start for a grade made
    in code (its ``table.copy()`` changed, then ``ColorLut(changed)``)."""
    axis = np.linspace(0.0, 1.0, size, dtype=np.float32)
    b, g, r = np.meshgrid(axis, axis, axis, indexing="ij")
    return ColorLut(np.stack([r, g, b], axis=-1), name=name)


def load_cube_lut(path: str | Path) -> ColorLut:
    """Read an Adobe/IRIDAS ``.cube`` 3D table (see the module docstring)."""
    path = Path(path)
    what = f"colour table {str(path)!r}"
    check_asset_file(path, what, MAX_LUT_FILE_BYTES)
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise AssetError(f"{what}: not a text file ({exc.reason} at byte {exc.start})") from None
    except OSError as exc:
        raise AssetError(f"{what}: {exc.strerror or exc}") from None
    title, size = path.stem, None
    domain = {"DOMAIN_MIN": (0.0, 0.0, 0.0), "DOMAIN_MAX": (1.0, 1.0, 1.0)}
    rows: list[str] = []
    first_row = 0
    for number, line in enumerate(text.splitlines(), 1):
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        word = line.split(None, 1)[0]
        if word[0].isalpha() and not _is_number(word):  # (nan and inf are numbers, found not finite below)
            if rows:
                raise AssetError(f"{what}, line {number}: {word} after the table's first row")
            rest = line[len(word):].strip()
            if word == "TITLE":
                title = rest.strip('"') or title
            elif word == "LUT_1D_SIZE":
                raise AssetError(f"{what}, line {number}: a 1D table (LUT_1D_SIZE); the engine reads 3D tables "
                                 "(LUT_3D_SIZE): export the grade as a 3D LUT")
            elif word == "LUT_3D_SIZE":
                if not rest.isdigit() or not 2 <= int(rest) <= MAX_LUT_SIZE:
                    raise AssetError(f"{what}, line {number}: LUT_3D_SIZE must be an integer from 2 to "
                                     f"{MAX_LUT_SIZE}, got {rest!r}")
                size = int(rest)
            elif word in domain:
                domain[word] = _three(rest, what, number, word)
            elif word == "LUT_3D_INPUT_RANGE":
                low, high = _numbers(rest, 2, what, number, word)
                domain["DOMAIN_MIN"], domain["DOMAIN_MAX"] = (low,) * 3, (high,) * 3
            else:
                raise AssetError(f"{what}, line {number}: unknown keyword {word!r} (TITLE, LUT_3D_SIZE, DOMAIN_MIN, "
                                 "DOMAIN_MAX are read)")
            continue
        if not rows:
            first_row = number
        rows.append(line)
    if size is None:
        raise AssetError(f"{what}: no LUT_3D_SIZE line (not a 3D .cube table)")
    if len(rows) != size ** 3:
        raise AssetError(f"{what}: LUT_3D_SIZE {size} needs {size ** 3} rows of three numbers, got {len(rows)}")
    uneven = next((i for i, row in enumerate(rows) if len(row.split()) != 3), None)
    if uneven is not None:
        raise AssetError(f"{what}, line {_row_line(text, first_row, uneven)}: {rows[uneven]!r} is not three numbers")
    try:
        values = np.array(" ".join(rows).split(), np.float64)
    except ValueError:
        bad = next(i for i, row in enumerate(rows) if not _is_numbers(row))
        raise AssetError(f"{what}, line {_row_line(text, first_row, bad)}: {rows[bad]!r} is not three "
                         "numbers") from None
    if not np.isfinite(values).all():
        bad = int(np.argmin(np.isfinite(values).reshape(-1, 3).all(axis=1)))
        raise AssetError(f"{what}, line {_row_line(text, first_row, bad)}: {rows[bad]!r} is not finite")
    table = values.reshape(size, size, size, 3)  # red fastest: [b][g][r]
    try:
        lut = ColorLut(table, name=title, domain_min=domain["DOMAIN_MIN"], domain_max=domain["DOMAIN_MAX"])
    except AssetError as exc:
        raise AssetError(f"{what}: {str(exc).split(': ', 1)[-1]}") from None
    lut.source = {"file": str(path)}
    return lut


def _numbers(text: str, count: int, what: str, number: int, word: str) -> tuple[float, ...]:
    parts = text.split()
    try:
        values = tuple(float(p) for p in parts)
    except ValueError:
        values = ()
    if len(values) != count or not all(map(math.isfinite, values)):
        raise AssetError(f"{what}, line {number}: {word} must be {count} numbers, got {text!r}")
    return values


def _three(text: str, what: str, number: int, word: str) -> tuple[float, float, float]:
    r, g, b = _numbers(text, 3, what, number, word)
    return r, g, b


def _is_number(word: str) -> bool:
    try:
        float(word)
    except ValueError:
        return False
    return True


def _is_numbers(row: str) -> bool:
    try:
        return len([float(p) for p in row.split()]) == 3
    except ValueError:
        return False


def _row_line(text: str, first_row: int, index: int) -> int:
    """The file's line number of the table's row ``index`` (blank and comment lines skipped)."""
    seen = -1
    for number, line in enumerate(text.splitlines(), 1):
        if number < first_row or not line.split("#", 1)[0].strip():
            continue
        seen += 1
        if seen == index:
            return number
    return first_row
