"""Particles in the benchmark ring: what living particles cost a frame.

``SparkRing(mirrors, particles)``: the mirror ring (``benchmarks.mirrors.MirrorRing``) with two
emitters at its centre keeping about ``particles`` alive between them: sparks (additive,
streaked, falling and bouncing on the floor) and smoke (alpha, lit, soft: sorted farthest
first in every view, lit with the sun's shadow, its depth copied a pass).  ``python -m
benchmarks ab OLD NEW --scenes sparks_8_2000`` or ``cpu``'s ``make_scene("sparks_8_2000")``:
against ``mirrors_8`` it is what the particles add (the step and rows on the CPU, an upload a
frame, two draws and a sort a view).
"""
from __future__ import annotations

from benchmarks.mirrors import MirrorRing
from components import ParticleEmitter, Transform
from engine import World

LIFETIME = 2.0  # seconds each lives: the rates are particles / LIFETIME


class SparkRing(MirrorRing):
    """The ring of ``mirrors`` mirrors with sparks and smoke keeping ``particles`` alive."""

    title = "benchmark: particles"

    def __init__(self, mirrors: int, particles: int) -> None:
        super().__init__(mirrors)
        self.particles = particles

    def build(self, world: World) -> None:
        super().build(world)
        if not self.particles:
            return
        half = self.particles / 2.0
        world.spawn(Transform(position=(0.0, 0.3, 0.0)),
                    ParticleEmitter(rate=half / LIFETIME, lifetime=LIFETIME, speed=(2.0, 3.5), spread=30.0,
                                    gravity=(0.0, -9.8, 0.0), ground=0.0, bounce=0.4, stretch=0.03,
                                    size=(0.05, 0.02), color=(4.0, 1.5, 0.3, 1.0), max_particles=self.particles,
                                    seed=1))
        world.spawn(Transform(position=(0.0, 0.5, 0.0)),
                    ParticleEmitter(rate=half / LIFETIME, lifetime=LIFETIME, speed=(0.3, 0.6), spread=20.0,
                                    size=(0.2, 0.8), color=(0.7, 0.7, 0.7, 0.5), blend="alpha", lit=True,
                                    softness=0.2, max_particles=self.particles, seed=2))
