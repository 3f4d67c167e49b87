"""Pose rows: every posed entity's joint matrices and morph weights in one float texture.

A row a posed entity (a ``Skin``, a ``Morph`` or both), RGBA32F: three texels a joint, the
first three rows of its matrix (the fourth is 0, 0, 0, 1: the matrices are affine), then at
``WEIGHTS_AT`` its morph targets' weights, four a texel.  The SKINNED and MORPHED builds read
them with ``texelFetch`` (``shaders/include/pose.glsl``)
at their draw's ``pose_row``.  A texture, not uniform arrays: GL 4.1 promises a vertex stage
1,024 uniform components, 85 joints at the most, shared with everything else a build reads; a
texture row holds ``MAX_JOINTS`` and every view, shadow map and probe face reads the same one
without a write a pass, and a new pose is one write a frame.  Rows are given out as posed
entities come and taken back as they go (the texture itself released with the last); the
texture doubles its rows when full (its rows kept on the CPU, sent again whole) up to
``GL_MAX_TEXTURE_SIZE`` posed entities, past which a GLLimitError names the entity.

While per-object motion blur is on (``track``: ``engine/render/object_motion.py``) a second
texture, ``before``, holds every row as it was at the end of the last frame (a row written
last frame is copied across when the next starts; a row new this frame starts as it is), so
the OBJECT_MOTION builds pose each vertex where it was too: a waving arm streaks.
"""
from __future__ import annotations

from collections.abc import Sequence

import moderngl
import numpy as np

from components.limits import MAX_JOINTS, MAX_MORPH_TARGETS
from engine.core.errors import GLLimitError

TEXELS_PER_JOINT = 3
WEIGHTS_AT = TEXELS_PER_JOINT * MAX_JOINTS       # the texel a row's morph weights start at
ROW_TEXELS = WEIGHTS_AT + -(-MAX_MORPH_TARGETS // 4)
FIRST_ROWS = 4  # rows the texture is made with


def skinning_defines(skinning: str) -> dict[str, str]:
    """The build defines of a batch bent by a Skin blending its joints by ``skinning``
    (``Skin.skinning``; "": no Skin): ``SKINNED``, and ``DUAL_QUATERNION_SKINNING`` for
    "dual_quaternion" (``shaders/include/pose.glsl``).  The scene's builds and the casters'."""
    if not skinning:
        return {}
    if skinning == "dual_quaternion":
        return {"SKINNED": "1", "DUAL_QUATERNION_SKINNING": "1"}
    return {"SKINNED": "1"}


class PoseRows:
    """The pose texture and which row each posed entity has."""

    def __init__(self, ctx: moderngl.Context, max_rows: int) -> None:
        self.ctx = ctx
        self.max_rows = max_rows
        self.texture: moderngl.Texture | None = None
        self.version = 0  # moved on when the texture is made again (what holds it binds the new one)
        self._rows: dict[int, int] = {}
        self._free: list[int] = []
        self._kept = np.zeros((0, ROW_TEXELS, 4), np.float32)  # every row, as sent
        # Last frame's rows (track): the texture and the rows written since the frame began.
        self.before: moderngl.Texture | None = None
        self._written: set[int] = set()
        self._new: set[int] = set()   # rows taken this frame (their before is their first pose)
        self._tracking = False        # track's last word

    def __len__(self) -> int:
        return len(self._rows)

    def write(self, entity: int, joints: np.ndarray | None, weights: Sequence[float] | None) -> int:
        """Put ``entity``'s joint matrices (J, 4, 4) and morph ``weights`` in its row (given
        one the first time); returns the row."""
        row = self._rows.get(entity)
        if row is None:
            row = self._take_row(entity)
            self._new.add(row)
        self._written.add(row)
        kept = self._kept[row]
        if joints is not None:
            texels = np.ascontiguousarray(joints[:, :3, :], np.float32).reshape(-1, 4)  # a joint's 3 rows
            kept[: len(texels)] = texels
            self.texture.write(texels.tobytes(), viewport=(0, row, len(texels), 1))
        if weights is not None:
            packed = np.zeros(ROW_TEXELS - WEIGHTS_AT, (np.float32, 4))
            packed.reshape(-1)[: len(weights)] = weights
            kept[WEIGHTS_AT:] = packed
            self.texture.write(packed.tobytes(), viewport=(WEIGHTS_AT, row, len(packed), 1))
        return row

    @property
    def moved(self) -> bool:
        """Whether a pose was written this frame while ``before`` is kept (it may have moved)."""
        return self.before is not None and bool(self._written)

    def track(self, on: bool, dt: float) -> bool:
        """Start a frame (the extract stage, before its writes): with ``on``, ``before`` gets
        last frame's rows (those written in it copied across; ``dt`` 0 keeps it as it is);
        without, it is released.  Returns whether ``before`` changed (what was drawn with it
        is not kept: a pose that stopped has no streak)."""
        self._tracking = on
        if not on or self.texture is None:
            if self.before is not None:
                self.before.release()
                self.before = None
                self.version += 1
            self._written.clear()
            self._new.clear()
            return False
        changed = False
        if self.before is None:
            self.before = self._texture(self._kept)   # (as it is now: nothing moved yet)
            self.version += 1
        elif dt > 0.0 and self._written:
            self._copy_before(self._written)
            changed = True
        if dt > 0.0:
            self._written.clear()
        self._new.clear()
        return changed

    def settle_new(self) -> None:
        """Rows first written this frame start ``before`` as they are (the prepare stage, after
        the extract stage's writes): a thing just posed did not move.  The first posed entity
        while tracking gets ``before`` made here (no draw reads a texture not made)."""
        if self._tracking and self.texture is not None and self.before is None:
            self.before = self._texture(self._kept)
            self.version += 1
            self._new.clear()
        if self.before is not None and self._new:
            self._copy_before(self._new)
            self._new.clear()

    def _copy_before(self, rows: set[int]) -> None:
        for row in sorted(rows):
            if row < self.before.height:
                self.before.write(self._kept[row].tobytes(), viewport=(0, row, ROW_TEXELS, 1))

    def _texture(self, rows: np.ndarray) -> moderngl.Texture:
        # Filled from the start (a GPU does not zero a new texture): every texel is some row's.
        texture = self.ctx.texture((ROW_TEXELS, len(rows)), 4, rows.tobytes(), dtype="f4")
        texture.filter = (moderngl.NEAREST, moderngl.NEAREST)
        texture.repeat_x = texture.repeat_y = False
        return texture

    def free(self, entity: int) -> None:
        """``entity`` has no pose drawn any more: its row is given back; the last one's takes the texture."""
        row = self._rows.pop(entity, None)
        if row is None:
            return
        self._free.append(row)
        if not self._rows:
            self.release()

    def _take_row(self, entity: int) -> int:
        if not self._free:
            self._grow(entity)
        row = self._free.pop()
        self._rows[entity] = row
        return row

    def _grow(self, entity: int) -> None:
        """Twice the rows (or the first ones), the rows written so far sent again whole."""
        held = len(self._kept)
        if held >= self.max_rows:
            raise GLLimitError(f"entity {entity}: a Skin or Morph past this OpenGL's {self.max_rows} posed entities "
                               "(the pose texture's rows: GL_MAX_TEXTURE_SIZE)")
        rows = min(max(FIRST_ROWS, 2 * held), self.max_rows)
        kept = np.zeros((rows, ROW_TEXELS, 4), np.float32)
        kept[:held] = self._kept
        self._kept = kept
        if self.texture is not None:
            self.texture.release()
        self.texture = self._texture(kept)
        if self.before is not None:   # (grown mid-frame: last frame's rows as the old one held them)
            held_before = np.zeros_like(kept)
            held_before[:held] = np.frombuffer(self.before.read(), np.float32).reshape(held, ROW_TEXELS, 4)
            self.before.release()
            self.before = self._texture(held_before)
        self.version += 1
        self._free.extend(range(rows - 1, held - 1, -1))  # the lowest first

    def release(self) -> None:
        if self.texture is not None:
            self.texture.release()
            self.texture = None
            self.version += 1
        if self.before is not None:
            self.before.release()
            self.before = None
        self._rows.clear()
        self._free.clear()
        self._kept = self._kept[:0]
