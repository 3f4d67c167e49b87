"""Per-object motion for motion blur: how each instance that moved this frame moved, as the
scene pass's vertex stage reads it (``shaders/include/object_motion.glsl``).

While the active camera's ``MotionBlur`` streaks moving things (``objects``), the extract
stage hands every mover's model matrix before and after its move (``note``: the instance
row's as it was, and as it is written), and the prepare stage sends one record a mover: the
matrix taking where a point of it is now to where it was (last frame's model matrix times the
inverse of this one), sorted by entity, in one float texture (``upload``).  Every scene
program is then built with ``OBJECT_MOTION``: its vertex stage finds its instance's record
(a binary search; none: it did not move), projects the point's place last frame with the
view's own projection, and the fragment writes the difference into the seen image's third
and fourth channels (``shaders/include/way.glsl`` ``seen_moved``), which composites carry up
the view tree as they carry the way: a thing moving in a mirror streaks as its reflection
moves.  The main tree's level targets get four-channel seen images only while this is on
(``LevelStack.seen_channels``: a wider image costs every pixel of every view its bandwidth).

A mover carried through a portal this frame (``PortalCrossings``) has its last place carried
with it (its crossing's transform times its last matrix), so it streaks by its motion, not
across the room.  A frame of dt 0 (a second presentation, a paused game) keeps the last
frame's records.  A skinned or morphed mesh's pose is followed as well: the pose texture
keeps last frame's rows while this is on (``PoseRows.track``), and the posed builds put each
vertex where last frame's joints and weights had it before the mover's record moves it.  What
is followed elsewhere: a moving mirror or portal (``SurfaceMotion``: its composite adds what
its motion moved, ``engine/render/mirror_passes.py``).  Not followed: particles.

Limit: ``OBJECT_MOTION_WIDTH`` x GL_MAX_TEXTURE_SIZE / 4 movers a frame (past it a
``GLLimitError``).  An entity's id is held as its bits from 12 up and its low 12, two floats
each exact, so any id is found.
"""
from __future__ import annotations

from collections.abc import Iterable

import moderngl
import numpy as np

from engine.core.errors import GLLimitError
from engine.render.pose_rows import PoseRows
from engine.resources import PortalCrossing

OBJECT_MOTION_WIDTH = 4096   # texels a row of the motion texture (a record is four: 1,023 a row after the count)
_HEADER_TEXELS = 4           # texel 0 holds the count; records start after four (whole records a row)
_LOW_BITS = 12               # an id's low bits, held apart from the rest (each part exact in a float32)
_SINGULAR = 1e-12            # |det| below this: a matrix with no inverse (a scale of 0), no motion


class ObjectMotion:
    """The frame's movers and the texture the scene programs read them from."""

    def __init__(self, ctx: moderngl.Context, max_texture_size: int, poses: PoseRows) -> None:
        self.ctx = ctx
        self.poses = poses   # the posed meshes' rows (their last frame's too while on: PoseRows.track)
        self.on = False
        self.texture: moderngl.Texture | None = None
        self.version = 0   # moved on when the texture is made again (a draw record binds the new one)
        self._max_rows = max_texture_size
        # The movers noted: (entities, models before, models now), float32 column-major rows of 16.
        self._chunks: list[tuple[list[int], np.ndarray, np.ndarray]] = []
        self._fresh = False   # something was noted this frame
        self._carried: dict[int, np.ndarray] = {}   # entity -> its crossings' transform this frame
        self._sent: bytes | None = None                  # the records the texture holds
        self.count = 0                                   # movers in the texture (0: nothing moved)

    @property
    def moving(self) -> bool:
        """Whether anything moved by its own motion this frame (a mover's matrix or a pose)."""
        return self.count > 0 or self.poses.moved

    @property
    def defines(self) -> tuple[tuple[str, str], ...]:
        """The scene programs' defines: ``OBJECT_MOTION`` while on."""
        return (("OBJECT_MOTION", "1"),) if self.on else ()

    def begin(self, on: bool, dt: float, crossings: Iterable[PortalCrossing] = ()) -> bool:
        """Start a frame's notes (``on``: the camera's motion blur streaks moving things; ``dt``
        0 keeps last frame's movers unless something moves); returns whether ``on`` changed
        (the scene programs and the level targets are built again)."""
        changed = on != self.on
        self.on = on
        self._fresh = False
        if dt > 0.0 or not on:   # (dt 0: last frame's movers and crossings are kept)
            self._chunks = []
            carried = {}
            for crossing in crossings:   # (in order: a second crossing carries the first's result)
                step = np.array(crossing.carry.to_list(), np.float64).T   # (glm lists columns)
                carried[crossing.entity] = step @ carried.get(crossing.entity, np.eye(4))
            self._carried = carried
        if not on:
            self.release()
        return changed

    def note(self, entities: list[int], before: np.ndarray, now: np.ndarray) -> None:
        """``entities`` (each once a frame) moved: their model matrices (column-major float32
        rows of 16, as the instance rows hold them) ``before`` and ``now``."""
        if not self._fresh:   # (the first this frame: a frame of dt 0 drops last frame's)
            self._chunks, self._fresh = [], True
        self._chunks.append((entities, before, now.copy()))

    def records(self) -> tuple[np.ndarray, np.ndarray]:
        """The frame's movers: their entities (sorted, int64) and each one's matrix taking a
        point's place now to its place last frame (float64, (n, 4, 4), rows); one whose
        matrix is the same, or has no inverse (a scale of 0), is left out."""
        chunks = self._chunks
        if not chunks:
            return np.zeros(0, np.int64), np.zeros((0, 4, 4))
        if len(chunks) == 1:
            entities, before, now = chunks[0]
            entities = np.array(entities, np.int64)
        else:
            entities = np.array([entity for chunk in chunks for entity in chunk[0]], np.int64)
            before, now = np.concatenate([chunk[1] for chunk in chunks]), np.concatenate([chunk[2] for chunk in chunks])
        moved = np.flatnonzero((before != now).any(axis=1))
        if len(moved) < len(entities):
            entities, before, now = entities[moved], before[moved], now[moved]
        before = before.reshape(-1, 4, 4).transpose(0, 2, 1).astype(np.float64)   # column-major -> rows
        now = now.reshape(-1, 4, 4).transpose(0, 2, 1).astype(np.float64)
        if self._carried:
            for at, entity in enumerate(entities.tolist()):
                carry = self._carried.get(entity)
                if carry is not None:
                    before[at] = carry @ before[at]
        try:
            back = before @ np.linalg.inv(now)
        except np.linalg.LinAlgError:   # (one scaled to nothing: it alone is left out)
            kept = np.abs(np.linalg.det(now)) > _SINGULAR
            entities, back = entities[kept], before[kept] @ np.linalg.inv(now[kept])
        order = np.argsort(entities)
        return entities[order], back[order]

    def upload(self) -> bool:
        """Send the frame's records (while on); returns whether what the texture holds changed
        (the levels drawn with the last ones are not kept: a thing that stopped has no streak)."""
        if not self.on:
            return False
        entities, back = self.records()
        count = len(entities)
        texels = np.zeros((_HEADER_TEXELS + 4 * count, 4), np.float32)
        texels[0, 0] = count
        if count:
            records = texels[_HEADER_TEXELS:].reshape(count, 4, 4)
            records[:, :3] = back[:, :3]
            records[:, 3, 2] = entities >> _LOW_BITS
            records[:, 3, 3] = entities & ((1 << _LOW_BITS) - 1)
        data = texels.tobytes()
        rows = -(-len(texels) // OBJECT_MOTION_WIDTH)
        if self.texture is None or self.texture.height < rows:
            self._make(rows, count)
        elif data == self._sent:
            return False
        if rows == 1:
            self.texture.write(data, viewport=(0, 0, len(texels), 1))
        else:
            whole = np.zeros((rows * OBJECT_MOTION_WIDTH, 4), np.float32)
            whole[: len(texels)] = texels
            self.texture.write(whole.tobytes(), viewport=(0, 0, OBJECT_MOTION_WIDTH, rows))
        changed = count > 0 or self.count > 0
        self._sent, self.count = data, count
        return changed

    def _make(self, rows: int, count: int) -> None:
        """The texture with at least ``rows`` rows (twice what it had), filled with zeros (a
        GPU does not clear a new texture: the count a reader finds first is 0)."""
        held = self.texture.height if self.texture is not None else 0
        rows = max(rows, 2 * held, 1)
        if rows > self._max_rows:
            raise GLLimitError(f"{count} moving entities in a frame: per-object motion blur holds "
                               f"{(self._max_rows * OBJECT_MOTION_WIDTH - _HEADER_TEXELS) // 4} "
                               "(the motion texture's rows: GL_MAX_TEXTURE_SIZE)")
        if self.texture is not None:
            self.texture.release()
        zeros = bytes(OBJECT_MOTION_WIDTH * rows * 16)
        self.texture = self.ctx.texture((OBJECT_MOTION_WIDTH, rows), 4, zeros, dtype="f4")
        self.texture.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self.texture.repeat_x = self.texture.repeat_y = False
        self.version += 1
        self._sent = None

    def release(self) -> None:
        if self.texture is not None:
            self.texture.release()
            self.texture = None
            self.version += 1
        self._sent, self.count = None, 0


def glsl_defines() -> dict[str, str]:
    return {"OBJECT_MOTION_WIDTH": str(OBJECT_MOTION_WIDTH)}


__all__ = ["OBJECT_MOTION_WIDTH", "ObjectMotion", "glsl_defines"]
