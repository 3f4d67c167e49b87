"""The living particles of one emitter, as arrays: spawned, moved and aged a frame at a time.

One ``ParticleCloud`` an emitter (``components/particles.py`` ``ParticleEmitter``), held by
the particles stage (``systems/particle_system.py``).  A frame's step is a fixed handful of
numpy calls whatever the count: the dead dropped (a boolean mask), the living moved (gravity
then drag, exactly: the velocity keeps exp(-drag dt) of itself), the new ones spawned.  New
particles are spread evenly through the frame: each is born at its own moment of it, at
where the emitter was then (its place between last frame's and this frame's, a straight
line) and already moved for the rest of the frame, so a fast emitter leaves an even trail,
not a clump a frame.

``rows`` is what a view draws: a row a particle of ``ROW_FLOATS`` float32 (world position,
size, linear colour and alpha, angle in radians, flipbook frame, streak), its size, colour and
frame worked out from its age over its life, oldest first (the order they were born); a
ribbon's rows hold its share of its life and its portal crossings in the angle's and frame's
places.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from pyglm import glm

from components.particles import ParticleEmitter
from components.transform import SCALE_RANGE

_NONE = np.zeros((0, 3))  # no particle died

# An open portal as the step's crossing test reads it: its world plane (4,), world -> its local
# space (4, 4), half its rectangle (2,) and the pair transform (4, 4: it carries positions,
# and its 3x3 part velocities, scaled where the pair's portals differ in scale), as numpy
# arrays of engine/rules/portal_gates.PortalGate's (the particles stage makes them).
# (plane, to_local, half, carry, the plane and to_local as it stood at the end of the
# last frame: the same arrays where it did not slide since)
Gate = tuple[np.ndarray, np.ndarray, tuple[float, float], np.ndarray, np.ndarray, np.ndarray]

# A drawn particle: x, y, z, size, r, g, b, a, angle, frame, and its streak (x, y, z: its
# velocity x ParticleEmitter.stretch, world; 0 for a square).  A ribbon's point (ParticleEmitter.
# ribbon): its life share (0 newborn, 1 dying) for the angle, its portal crossings for the frame.
ROW_FLOATS = 13
ROW_POSITION, ROW_SIZE, ROW_COLOR, ROW_ANGLE, ROW_FRAME = slice(0, 3), 3, slice(4, 8), 8, 9
ROW_STREAK = slice(10, 13)


class ParticleCloud:
    """What lives of one emitter's particles (positions in the world, or in the emitter's
    frame for ``space`` "local"), its random stream (from its ``seed``) and the share of a
    particle its rate carries over to the next frame."""

    def __init__(self, seed: int, capacity: int) -> None:
        self.rng = np.random.default_rng(seed)
        self.position = np.zeros((0, 3))
        self.velocity = np.zeros((0, 3))
        self.age = np.zeros(0)
        self.life = np.ones(0)
        self.angle = np.zeros(0)
        self.spin = np.zeros(0)
        self.crossed = np.zeros(0)  # portals each has been carried through (a ribbon breaks between counts)
        self.grow = np.ones(0)     # each one's size over the emitter's: a portal pair of two scales scaled it
        self.carry = 0.0       # the part of a particle the rate owes (spawned once it reaches 1)
        self.capacity = capacity
        self.capped = 0        # particles the last step could not spawn (max_particles reached)
        self.last_origin: glm.mat4 | None = None  # the emitter's matrix at the last step
        self.was_playing = False
        self._mesh = None      # the entity's mesh this step (shape "mesh")
        self.died = _NONE      # where the last step's dead died (world): a sub-emitter's bursts are born there
        self._surface = None   # (mesh, its triangles' corners, their normals, their areas' running shares)

    @property
    def count(self) -> int:
        return len(self.age)

    def step(self, emitter: ParticleEmitter, matrix: glm.mat4, dt: float, bursts: int = 0,
             gates: Sequence[Gate] = (), mesh: Any = None) -> None:
        """One frame of ``dt`` seconds of ``emitter`` (a ParticleEmitter) whose entity's
        model-to-world matrix is now ``matrix``: age, drop the dead, move (through ``gates``,
        the open portals, world-space particles), spawn (``bursts``: its ``burst_on`` events
        fired this frame, a burst each; ``mesh``: the entity's, for ``shape`` "mesh")."""
        self._mesh = mesh
        local = emitter.space == "local"
        previous = self.last_origin if self.last_origin is not None else matrix
        self.last_origin = glm.mat4(matrix)
        self.capacity = emitter.max_particles
        self.capped = 0
        self.died = _NONE
        if dt > 0.0 and self.count:
            self.age += dt
            alive = self.age < self.life
            if not alive.all():
                dead = self.position[~alive]
                if local:  # (where they died in the world: a sub-emitter's bursts are born there)
                    m = np.array(matrix)
                    dead = dead @ m[:3, :3].T + m[:3, 3]
                self.died = dead
                self._keep(alive)
            gravity = np.array(emitter.gravity, dtype=np.float64)
            if local and gravity.any():  # (the pull is the world's: into the emitter's frame)
                gravity = np.array(glm.inverse(glm.mat3(matrix)) * glm.vec3(*gravity))
            before = self.position.copy() if gates and not local else None
            self._move(slice(None), dt, gravity, emitter.drag)
            if emitter.ground is not None:
                self._bounce(slice(None), emitter.ground, emitter.bounce)
            if before is not None:
                self._through(before, gates)
        if len(self.age) > self.capacity:  # (max_particles lowered: the oldest go)
            self._keep(np.sort(np.argsort(self.life - self.age)[-self.capacity:]))  # (in the order born)
        starting = emitter.playing and not self.was_playing
        self.was_playing = emitter.playing
        ages = np.zeros(0)
        if emitter.playing and emitter.rate > 0.0 and dt > 0.0:
            # Births every 1 / rate seconds, the first when the share carried from the last
            # frame makes a whole particle: each one's age at the frame's end.
            owed = self.carry + emitter.rate * dt
            streamed = int(owed)
            # (only the youngest that could live are made: a long frame at a high rate asks
            # for more than max_particles, and the rest are counted as capped, not built)
            first = max(streamed - self.capacity, 0)
            ages = np.maximum(dt - (np.arange(first, streamed) + 1.0 - self.carry) / emitter.rate, 0.0)
            self.capped += first
            self.carry = owed - streamed
        elif not emitter.playing:
            self.carry = 0.0
        # (with burst_on the bursts come on its events instead of as it starts)
        bursting = (int(starting and not emitter.burst_on) + (bursts if emitter.playing else 0)) * emitter.burst
        if bursting:  # a burst is born at once, at the frame's end
            ages = np.concatenate([ages, np.zeros(min(bursting, self.capacity))])
            self.capped += max(bursting - self.capacity, 0)
        if len(ages):
            room = max(self.capacity - self.count, 0)
            self.capped += max(len(ages) - room, 0)
            self._spawn(emitter, ages[len(ages) - room:] if len(ages) > room else ages, matrix, previous, dt, local)

    def _keep(self, which) -> None:
        for name in ("position", "velocity", "age", "life", "angle", "spin", "crossed", "grow"):
            setattr(self, name, getattr(self, name)[which])

    def _move(self, which, dt, gravity: np.ndarray, drag: float) -> None:
        """Move the particles ``which`` on by ``dt`` (one number, or one a particle) under
        ``gravity`` and ``drag``: dv/dt = g - drag v, solved exactly over the step."""
        dt = np.asarray(dt, dtype=np.float64).reshape(-1, 1) if np.ndim(dt) else dt
        v = self.velocity[which]
        if drag > 0.0:
            keep = np.exp(-drag * dt)
            # x(t) = x0 + g t / k + (v0 - g / k) (1 - e^-kt) / k ; v(t) = g / k + (v0 - g / k) e^-kt
            terminal = gravity / drag
            moved = terminal * dt + (v - terminal) * ((1.0 - keep) / drag)
            self.velocity[which] = terminal + (v - terminal) * keep
        else:
            moved = v * dt + 0.5 * gravity * (dt * dt)
            self.velocity[which] = v + gravity * dt
        self.position[which] = self.position[which] + moved

    def burst_at(self, emitter: ParticleEmitter, points: np.ndarray, matrix: glm.mat4) -> None:
        """``emitter``'s ``burst`` born at each of ``points`` (world) now, by its shape, cone
        and speeds as at its own place (a sub-emitter's: ``ParticleEmitter.on_death``); its
        entity's model-to-world matrix is ``matrix``.  Past its room, counted as capped."""
        if not len(points) or not emitter.burst:
            return
        origins = np.repeat(np.asarray(points, np.float64), emitter.burst, axis=0)
        room = max(self.capacity - self.count, 0)
        self.capped += max(len(origins) - room, 0)
        origins = origins[:room]
        if len(origins):
            self._spawn(emitter, np.zeros(len(origins)), matrix, matrix, 0.0, emitter.space == "local", origins)

    def _through(self, before: np.ndarray, gates: Sequence[Gate]) -> None:
        """Carry each particle whose step from ``before`` went into a portal (from its front
        to its back, meeting its plane inside its rectangle, in the portal's own space: a
        portal that slid since the last frame from where it stood then) to the partner: its
        position and velocity by the pair transform, as a traveller is (the earliest gate a
        path meets; ``engine.rules.portal_gates``)."""
        n = len(before)
        best = np.full(n, np.inf)
        which = np.full(n, -1)
        for index, (plane, to_local, half, _, was_plane, was_to_local) in enumerate(gates):
            d0 = before @ was_plane[:3] + was_plane[3]
            d1 = self.position @ plane[:3] + plane[3]
            crossing = (d0 >= 0.0) & (d1 < 0.0)
            if not crossing.any():
                continue
            t = np.where(crossing, d0 / np.where(crossing, d0 - d1, 1.0), np.inf)
            step = np.minimum(t, 1.0)[:, None]
            local = (before @ was_to_local[:3, :3].T + was_to_local[:3, 3]) * (1.0 - step) \
                + (self.position @ to_local[:3, :3].T + to_local[:3, 3]) * step
            inside = crossing & (np.abs(local[:, 0]) <= half[0]) & (np.abs(local[:, 1]) <= half[1]) & (t < best)
            best[inside] = t[inside]
            which[inside] = index
        for index, (_, _, _, carry, _, _) in enumerate(gates):
            carried = which == index
            if carried.any():
                self.position[carried] = self.position[carried] @ carry[:3, :3].T + carry[:3, 3]
                self.velocity[carried] = self.velocity[carried] @ carry[:3, :3].T  # a scaled pair scales it
                self.crossed[carried] += 1.0
                k = abs(np.linalg.det(carry[:3, :3])) ** (1.0 / 3.0)
                if abs(k - 1.0) > 1e-6:  # out of a pair of two scales: as big as its view showed it
                    self.grow[carried] = np.clip(self.grow[carried] * k, *SCALE_RANGE)  # (a float32 row's size)

    def _bounce(self, which, ground: float, keep: float) -> None:
        """Particles ``which`` that went below ``ground`` this step: put back above it by
        ``keep`` of how far they went under, their fall turned upwards at ``keep`` of its
        speed (their slide along it left as it is)."""
        y = self.position[which, 1]
        under = y < ground
        if not under.any():
            return
        y[under] = ground + (ground - y[under]) * keep
        self.position[which, 1] = y
        vy = self.velocity[which, 1]
        vy[under] = np.abs(vy[under]) * keep
        self.velocity[which, 1] = vy

    def _spawn(self, emitter: ParticleEmitter, age: np.ndarray, matrix: glm.mat4, previous: glm.mat4, dt: float,
               local: bool, origins: np.ndarray | None = None) -> None:
        """New particles of ``emitter``, one an ``age`` (how long before the frame's end it
        was born), each at the emitter's place at its birth and moved on for the rest of the
        frame; ``origins`` (world, one a particle): born about those instead (``burst_at``)."""
        n = len(age)
        if n <= 0:
            return
        rng = self.rng
        if emitter.shape == "mesh":
            if self._mesh is None:  # (its MeshRef taken away: none born; the particles stage says so)
                return
            start, axes = self._surface_points(n)
            heading = self._headings(emitter, n, axes)
        else:
            start = self._start_points(emitter, n)
            heading = self._headings(emitter, n)
        lo, hi = emitter.speed
        speed = lo + (hi - lo) * rng.random(n)
        velocity = heading * speed[:, None]
        if origins is not None:  # about given world points: the shape turned as the emitter is
            m = np.array(matrix)
            if local:
                inverse = np.linalg.inv(m)
                position = start + (origins @ inverse[:3, :3].T + inverse[:3, 3])
            else:
                position = start @ m[:3, :3].T + origins
                along = velocity @ m[:3, :3].T
                norms = np.linalg.norm(heading @ m[:3, :3].T, axis=1)[:, None]
                velocity = along / np.maximum(norms, 1e-30)
        elif local:
            position = start
        else:
            # Into the world, each from where the emitter was at its moment (its place on the
            # line from last frame's matrix to this one's; turned as it is now).
            turn = np.array(glm.mat3(matrix)).T  # (numpy's copy of a glm matrix is row by row: M^T for row vectors)
            position = start @ turn + np.array(matrix[3].xyz)
            if dt > 0.0:
                back = (age / dt)[:, None]
                position -= back * (np.array(matrix[3].xyz) - np.array(previous[3].xyz))
            along = velocity @ turn
            norms = np.linalg.norm(heading @ turn, axis=1)[:, None]
            velocity = along / np.maximum(norms, 1e-30)  # (the emitter's scale sizes no speed)
        lo, hi = emitter.lifetime
        life = lo + (hi - lo) * rng.random(n)
        lo, hi = emitter.spin
        spin = np.radians(lo + (hi - lo) * rng.random(n))
        lo, hi = emitter.angle
        angle = np.radians(lo + (hi - lo) * rng.random(n))
        first = self.count
        self.position = np.concatenate([self.position, position])
        self.velocity = np.concatenate([self.velocity, velocity])
        self.age = np.concatenate([self.age, np.zeros(n)])
        self.life = np.concatenate([self.life, life])
        self.angle = np.concatenate([self.angle, angle])
        self.spin = np.concatenate([self.spin, spin])
        self.crossed = np.concatenate([self.crossed, np.zeros(n)])
        self.grow = np.concatenate([self.grow, np.ones(n)])
        born = slice(first, first + n)
        if age.any():  # each moved on for its part of the frame
            gravity = np.array(emitter.gravity, dtype=np.float64)
            if local and gravity.any():
                gravity = np.array(glm.inverse(glm.mat3(matrix)) * glm.vec3(*gravity))
            self._move(born, age, gravity, emitter.drag)
            if emitter.ground is not None:
                self._bounce(born, emitter.ground, emitter.bounce)
            self.age[born] = age
            self.angle[born] += self.spin[born] * age
        dead = self.age >= self.life  # (born so early in a long frame that it is gone already)
        if dead.any():
            self._keep(~dead)

    def _start_points(self, emitter: ParticleEmitter, n: int) -> np.ndarray:
        """``n`` points of the emitter's shape, in its frame."""
        rng = self.rng
        extent = np.array(emitter.extent, dtype=np.float64)
        if emitter.shape == "sphere":
            directions = _unit_vectors(rng, n)
            return directions * (extent[0] * np.cbrt(rng.random(n)))[:, None]
        if emitter.shape == "box":
            return (rng.random((n, 3)) * 2.0 - 1.0) * extent
        return np.zeros((n, 3))

    def _surface_points(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        """``n`` points spread evenly by area over the entity's mesh (a triangle chosen by its
        area, a point in it by uniform barycentric coordinates), and the face's unit normal
        at each: where ``shape`` "mesh" particles are born and which way they fly."""
        mesh = self._mesh
        kept = self._surface
        if kept is None or kept[0] is not mesh:
            corners = mesh.positions[mesh.indices].astype(np.float64)  # (T, 3, 3)
            cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
            area = np.linalg.norm(cross, axis=1)
            normals = cross / np.maximum(area, 1e-30)[:, None]
            kept = self._surface = (mesh, corners, normals, np.cumsum(area) / max(float(area.sum()), 1e-30))
        _, corners, normals, shares = kept
        rng = self.rng
        triangle = np.minimum(np.searchsorted(shares, rng.random(n), side="right"), len(shares) - 1)
        a, b = rng.random(n), rng.random(n)
        flip = a + b > 1.0
        a[flip], b[flip] = 1.0 - a[flip], 1.0 - b[flip]
        c = corners[triangle]
        points = c[:, 0] + a[:, None] * (c[:, 1] - c[:, 0]) + b[:, None] * (c[:, 2] - c[:, 0])
        return points, normals[triangle]

    def _headings(self, emitter: ParticleEmitter, n: int, axes: np.ndarray | None = None) -> np.ndarray:
        """``n`` unit vectors spread evenly over the cone of ``spread`` degrees about
        ``direction`` (uniform on the sphere's cap: its height uniform), or about each of
        ``axes`` (unit, one a particle: a mesh's face normals)."""
        rng = self.rng
        lowest = math.cos(math.radians(emitter.spread))
        cos_t = 1.0 - rng.random(n) * (1.0 - lowest)
        sin_t = np.sqrt(np.maximum(1.0 - cos_t * cos_t, 0.0))
        phi = rng.random(n) * (2.0 * math.pi)
        if axes is None:
            axes = np.array(emitter.direction, dtype=np.float64)[None, :]
            axes = axes / np.linalg.norm(axes)  # (unit in float32: made unit again in float64)
        helper = np.where((np.abs(axes[:, 0]) < 0.9)[:, None], (1.0, 0.0, 0.0), (0.0, 0.0, 1.0))
        u = np.cross(axes, helper)
        u /= np.linalg.norm(u, axis=1)[:, None]
        w = np.cross(axes, u)
        return (cos_t[:, None] * axes + (sin_t * np.cos(phi))[:, None] * u
                + (sin_t * np.sin(phi))[:, None] * w)

    def rows(self, emitter: ParticleEmitter, matrix: glm.mat4) -> np.ndarray:
        """The drawn rows (``ROW_FLOATS`` float32 a particle) of the living particles of
        ``emitter``, whose entity's model-to-world matrix is ``matrix``."""
        n = self.count
        out = np.empty((n, ROW_FLOATS), np.float32)
        if not n:
            return out
        t = np.clip(self.age / self.life, 0.0, 1.0)
        if emitter.space == "local":
            m = np.array(matrix)  # (row by row)
            out[:, ROW_POSITION] = self.position @ m[:3, :3].T + m[:3, 3]
            scale = glm.length(glm.vec3(matrix[0])) * glm.length(glm.vec3(matrix[1])) * glm.length(glm.vec3(matrix[2]))
            grow = scale ** (1.0 / 3.0)  # (a scaled emitter's cloud is scaled, its sprites with it)
        else:
            out[:, ROW_POSITION] = self.position
            grow = self.grow  # (1, but where a portal pair of two scales carried it)
        first, last = emitter.size
        if emitter.size_keys:
            keys = np.array(emitter.size_keys)
            out[:, ROW_SIZE] = np.interp(t, keys[:, 0], keys[:, 1]) * grow
        else:
            out[:, ROW_SIZE] = (first + (last - first) * t) * grow
        if emitter.color_keys:
            keys = np.array(emitter.color_keys)
            out[:, ROW_COLOR] = np.stack([np.interp(t, keys[:, 0], keys[:, 1 + c]) for c in range(4)], axis=1)
        else:
            start, end = np.array(emitter.color), np.array(emitter.final_color)
            out[:, ROW_COLOR] = start + (end - start) * t[:, None]
        if emitter.ribbon:  # a ribbon's point: how far along its life (its u), and its portal crossings
            out[:, ROW_ANGLE] = t
            out[:, ROW_FRAME] = self.crossed
        else:
            out[:, ROW_ANGLE] = self.angle + self.spin * self.age
            frames = emitter.frames
            out[:, ROW_FRAME] = np.minimum(np.floor(t * frames), frames - 1)
        if emitter.stretch > 0.0 and not emitter.ribbon:
            velocity = self.velocity if emitter.space == "world" else self.velocity @ m[:3, :3].T
            out[:, ROW_STREAK] = velocity * emitter.stretch
        else:
            out[:, ROW_STREAK] = 0.0
        return out


def _unit_vectors(rng: np.random.Generator, n: int) -> np.ndarray:
    """``n`` directions spread evenly over the sphere."""
    z = rng.random(n) * 2.0 - 1.0
    phi = rng.random(n) * (2.0 * math.pi)
    r = np.sqrt(np.maximum(1.0 - z * z, 0.0))
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)
