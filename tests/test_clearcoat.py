"""The clear coat (``Material.clearcoat``, glTF's ``KHR_materials_clearcoat``): a colourless
GGX layer of f0 0.04 over the material.  Checked against two other paths: a coat over a
black, unreflecting base shows exactly what a plain black dielectric of the coat's
roughness reflects (the same f0, the same split sum), and the base under the coat keeps
1 - F(n.v) of its light, F Schlick's for 0.04 at each pixel's angle, worked out here from
the pixels' rays and the sphere."""
from __future__ import annotations

import math

import numpy as np
import pytest
from pyglm import glm

from components import (
    ComponentValueError,
    DirectionalLight,
    Material,
    MeshRef,
    Mirror,
    PointLight,
    Skybox,
    Transform,
    look_rotation,
)
from engine.assets.mesh import quad, sphere
from tests.support import look_from, pixel_rays, srgb_to_linear

SIZE = (96, 72)
EYE = np.array([0.0, 0.0, 3.0])
RADIUS = 1.0
SKY = np.stack([np.full((8, 8, 3), v, np.float32) for v in (0.9, 0.2, 0.6, 0.3, 0.5, 0.7)])  # a sky with some shape


def ball(material: Material, sun: bool, lamp: bool = False):
    """The ball under the sky, with a sun, or with a lamp whose light also comes back off a
    mirror out of view on the left (a virtual light: light through mirrors)."""
    def build(world):
        look_from(world, tuple(EYE), (0.0, 0.0, 0.0), fov=50.0)
        world.spawn(Skybox(faces=SKY))
        if sun:
            world.spawn(DirectionalLight(direction=(-0.4, -0.5, -1.0), intensity=0.8, shadows=False))
        if lamp:
            world.spawn(Transform(position=(1.5, 1.0, 2.0)), PointLight(intensity=4.0, range=30.0))
            world.spawn(Transform(position=(-3.0, 0.0, 0.0), rotation=look_rotation(glm.vec3(-1.0, 0.0, 0.0))),
                        MeshRef(quad(4.0, 4.0)), Material(), Mirror(reflects_light=True))
        world.spawn(Transform(), MeshRef(sphere(RADIUS, 64, 32)), material)
    return build


def render(scene, material: Material, sun: bool = False, lamp: bool = False) -> tuple[np.ndarray, object]:
    runner = scene(ball(material, sun, lamp), SIZE)
    runner.engine.renderer.antialias = "off"
    runner.frame()
    return srgb_to_linear(runner.frame()), runner.engine.main_view


def sphere_pixels(view, rim: float = 0.15) -> tuple[np.ndarray, np.ndarray]:
    """Which pixels' rays meet the ball inside its outline (by ``rim`` of the radius squared
    in the ray's closest approach: the facets' normals differ most there), and n.v there."""
    eye, rays = pixel_rays(view, SIZE)
    b = (rays * (eye - 0.0)).sum(-1)
    c = float(np.dot(eye, eye)) - RADIUS ** 2
    disc = b * b - c
    inside = disc > rim * RADIUS ** 2
    t = -b - np.sqrt(np.maximum(disc, 0.0))
    normal = (eye + t[..., None] * rays) / RADIUS
    return inside, np.clip((normal * -rays).sum(-1), 0.0, 1.0)


BLACK_BASE = dict(color=(0.0, 0.0, 0.0, 1.0), roughness=1.0, environment_reflection=0.0)


@pytest.mark.parametrize("roughness", [0.05, 0.4])
def test_a_coat_over_black_reflects_the_sky_as_a_black_dielectric_of_its_roughness(scene, roughness):
    coated, view = render(scene, Material(**BLACK_BASE, clearcoat=1.0, clearcoat_roughness=roughness))
    plain, _ = render(scene, Material(color=(0.0, 0.0, 0.0, 1.0), roughness=roughness))
    inside, _ = sphere_pixels(view)
    assert plain[inside].max() > 0.05   # the sky's reflection, brightest at the rim
    np.testing.assert_allclose(coated[inside], plain[inside], atol=0.004, rtol=0.01)
    half, _ = render(scene, Material(**BLACK_BASE, clearcoat=0.5, clearcoat_roughness=roughness))
    np.testing.assert_allclose(half[inside], 0.5 * plain[inside], atol=0.004, rtol=0.02)


@pytest.mark.parametrize("light", ["sun", "lamp"])
def test_a_coats_highlight_is_a_black_dielectrics(scene, light):
    """With a sun, or a lamp and its image in a mirror: the coat's highlights too (the plain
    one's energy compensation, a few percent for f0 0.04 at this roughness, aside)."""
    lights = {"sun": light == "sun", "lamp": light == "lamp"}
    coated, view = render(scene, Material(**BLACK_BASE, clearcoat=1.0, clearcoat_roughness=0.3), **lights)
    plain, _ = render(scene, Material(color=(0.0, 0.0, 0.0, 1.0), roughness=0.3), **lights)
    sky_only, _ = render(scene, Material(color=(0.0, 0.0, 0.0, 1.0), roughness=0.3))
    inside, _ = sphere_pixels(view)
    highlight = inside & ((plain - sky_only)[..., 0] > 0.02)
    assert highlight.sum() > 10
    if light == "lamp":   # the lamp's own highlight on the right, its image's on the left
        columns = np.nonzero(highlight)[1]
        assert columns.min() < SIZE[0] // 2 - 5 and columns.max() > SIZE[0] // 2 + 5
    np.testing.assert_allclose(coated[highlight], plain[highlight], atol=0.004, rtol=0.04)


def test_the_base_under_a_coat_keeps_what_the_coats_fresnel_leaves(scene):
    """A rough red base, lit: coated less the coat over black is the base's light times
    1 - F(n.v), F = 0.04 + 0.96 (1 - n.v)^5 at each pixel."""
    red = dict(color=(0.7, 0.1, 0.05, 1.0), roughness=0.9, environment_reflection=0.0)
    coat = dict(clearcoat=1.0, clearcoat_roughness=0.1)
    coated_red, view = render(scene, Material(**red, **coat), sun=True)
    coated_black, _ = render(scene, Material(**BLACK_BASE, **coat), sun=True)
    bare_red, _ = render(scene, Material(**red), sun=True)
    bare_black, _ = render(scene, Material(**BLACK_BASE), sun=True)
    inside, nv = sphere_pixels(view, rim=0.06)
    base = (bare_red - bare_black)[..., 0]
    lit = inside & (base > 0.05) & (coated_red[..., 0] < 0.98)
    assert lit.sum() > 200
    fresnel = 0.04 + 0.96 * (1.0 - nv) ** 5
    np.testing.assert_allclose((coated_red - coated_black)[..., 0][lit], (base * (1.0 - fresnel))[lit],
                               atol=0.006, rtol=0.02)
    assert fresnel[lit].max() > 2.5 * fresnel[lit].min()   # angles from head on to near grazing


def test_clearcoat_values_are_checked():
    with pytest.raises(ComponentValueError, match=r"Material.clearcoat"):
        Material(clearcoat=1.5)
    with pytest.raises(ComponentValueError, match=r"Material.clearcoat_roughness"):
        Material(clearcoat_roughness=-0.1)


def test_a_gltf_clear_coat_reaches_the_material(tmp_path):
    from engine.assets.mesh import load_model
    from engine.assets.models import spawn_model
    from engine.core.errors import AssetError
    from engine.core.world import World
    from tests.test_materials_from_files import write_glb

    def material(coat: object) -> dict:
        return {"name": "paint", "pbrMetallicRoughness": {"baseColorFactor": [0.6, 0.0, 0.0, 1.0]},
                "extensions": {"KHR_materials_clearcoat": coat}}
    path = write_glb(tmp_path / "car.glb", sphere(0.5), material({"clearcoatFactor": 0.8,
                                                                  "clearcoatRoughnessFactor": 0.1}), [],
                     {"extensionsUsed": ["KHR_materials_clearcoat"], "extensionsRequired": ["KHR_materials_clearcoat"]})
    world = World("car")
    spawn_model(world, path)
    ((_, paint),) = list(world.query_one(Material))
    assert paint.clearcoat == pytest.approx(0.8) and paint.clearcoat_roughness == pytest.approx(0.1)
    bad = write_glb(tmp_path / "bad.glb", sphere(0.5), material({"clearcoatFactor": 3}), [])
    with pytest.raises(AssetError, match=r"bad\.glb.*'paint'.*clearcoatFactor must be a number in \[0, 1\], got 3"):
        load_model(bad)
    textured = write_glb(tmp_path / "textured.glb", sphere(0.5),
                         material({"clearcoatFactor": 1, "clearcoatNormalTexture": {"index": 0}}), [])
    with pytest.warns(UserWarning, match=r"'paint'.*clearcoatNormalTexture left out"):
        (part,) = load_model(textured)
    assert part.clearcoat == 1.0


@pytest.mark.parametrize("reflectance", [0.2, 1.0])
def test_a_dielectrics_reflectance_is_a_grey_metals_f0(scene, reflectance):
    """``Material.reflectance``: a black non-metal of reflectance r reflects head on as much as
    a metal of colour 0.16 r^2 (its f0): the two frames agree, sky, sun and all."""
    f0 = 0.16 * reflectance ** 2
    dielectric, view = render(scene, Material(color=(0.0, 0.0, 0.0, 1.0), roughness=0.3, reflectance=reflectance),
                              sun=True)
    metal, _ = render(scene, Material(color=(f0, f0, f0, 1.0), metallic=1.0, roughness=0.3), sun=True)
    default, _ = render(scene, Material(color=(0.0, 0.0, 0.0, 1.0), roughness=0.3), sun=True)
    inside, _ = sphere_pixels(view)
    np.testing.assert_allclose(dielectric[inside], metal[inside], atol=0.004, rtol=0.01)
    assert abs(float(np.median(dielectric[inside] - default[inside]))) > 0.004   # (not the default 0.04's)


def test_a_tinted_dielectrics_reflectance_is_a_coloured_metals_f0(scene):
    """``Material.specular_color``: a black non-metal of reflectance 0.8 tinted (1, 0.5, 0.2)
    reflects head on as a metal coloured 0.16 x 0.8^2 x the tint; a tint past 1 is held at 1 in
    that channel (as a white metal)."""
    f0 = 0.16 * 0.8 ** 2
    tint = (1.0, 0.5, 0.2)
    tinted, view = render(scene, Material(color=(0.0, 0.0, 0.0, 1.0), roughness=0.3, reflectance=0.8,
                                          specular_color=tint), sun=True)
    metal, _ = render(scene, Material(color=(f0 * tint[0], f0 * tint[1], f0 * tint[2], 1.0), metallic=1.0,
                                      roughness=0.3), sun=True)
    inside, _ = sphere_pixels(view)
    np.testing.assert_allclose(tinted[inside], metal[inside], atol=0.004, rtol=0.01)
    assert float(np.median(tinted[inside][:, 0] - tinted[inside][:, 2])) > 0.004   # (the red shows)
    held, _ = render(scene, Material(color=(0.0, 0.0, 0.0, 1.0), roughness=0.3, reflectance=1.0,
                                     specular_color=(10.0, 1.0, 1.0)), sun=True)
    white_red, _ = render(scene, Material(color=(1.0, 0.16, 0.16, 1.0), metallic=1.0, roughness=0.3), sun=True)
    np.testing.assert_allclose(held[inside], white_red[inside], atol=0.004, rtol=0.01)
    with pytest.raises(ComponentValueError, match=r"Material.specular_color must have every component in \[0, 10\]"):
        Material(specular_color=(11.0, 1.0, 1.0))


@pytest.mark.parametrize("extensions, reflectance", [
    ({}, 0.5),
    ({"KHR_materials_ior": {"ior": 2.0}}, math.sqrt(((1.0 / 3.0) ** 2) / 0.16)),
    ({"KHR_materials_specular": {"specularFactor": 0.5}}, math.sqrt(0.02 / 0.16)),
    ({"KHR_materials_ior": {"ior": 1.33}, "KHR_materials_specular": {"specularColorFactor": [1.0, 1.0, 1.0]}},
     math.sqrt(((0.33 / 2.33) ** 2) / 0.16)),
    # a tint: the reflectance from the largest channel, the tint the channels over it
    ({"KHR_materials_specular": {"specularColorFactor": [1.0, 0.5, 0.25]}}, 0.5),
    # past 16%: the reflectance held at 1, the tint carrying the rest (f0 0.4 = 0.16 x 2.5)
    ({"KHR_materials_specular": {"specularColorFactor": [10.0, 1.0, 1.0]}}, 1.0),
])
def test_a_gltf_ior_and_specular_set_the_reflectance(tmp_path, extensions, reflectance):
    from engine.assets.mesh import load_model
    from tests.test_materials_from_files import write_glb

    material = {"name": "m", "pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.5, 0.5, 1.0]},
                "extensions": extensions}
    (part,) = load_model(write_glb(tmp_path / "m.glb", sphere(0.5), material, []))
    assert part.reflectance == pytest.approx(reflectance, rel=1e-6)
    colour = extensions.get("KHR_materials_specular", {}).get("specularColorFactor", [1.0, 1.0, 1.0])
    ior = extensions.get("KHR_materials_ior", {}).get("ior", 1.5)
    factor = extensions.get("KHR_materials_specular", {}).get("specularFactor", 1.0)
    f0 = [min(((ior - 1) / (ior + 1)) ** 2 * c, 1.0) * factor for c in colour]   # (glTF's, channel by channel)
    assert [0.16 * reflectance ** 2 * t for t in part.specular_color] == pytest.approx(f0, rel=1e-6)


# Every view shades from its own eye: a mirror's view from the camera's image in the mirror's
# plane, a portal's from the eye carried through it.  What stands off to the camera's right
# (SEEN), out of its own sight, shows in a mirror at MIRROR_AT turned 30 degrees about y; the
# portal pair's B stands where that mirror does, facing the same way, and the camera before A
# is the one carried to the mirror's image eye (A turned otherwise, far away): so both
# reflections show what a camera at IMAGE_EYE looking at MIRROR_AT sees, the mirror's turned
# left for right.  tests/test_particles.py's in_a_mirror_and_from_its_eye is the model.
MIRROR_AT = glm.vec3(0.0, 0.0, -2.5)
MIRROR_TURN = glm.angleAxis(glm.radians(30.0), glm.vec3(0.0, 1.0, 0.0))
MIRROR_SIZE = (3.0, 2.4)
CAMERA_EYE = glm.vec3(0.0, 0.0, 1.0)   # (3.5 m before the mirror, looking at its middle)
SEEN = glm.vec3(2.2, 0.1, -1.3)
PORTAL_A = glm.vec3(20.0, 0.0, 20.0)
PORTAL_A_TURN = glm.angleAxis(glm.radians(-75.0), glm.vec3(0.0, 1.0, 0.0))
EYE_FOV = 40.0
EYE_SIZE = (64, 48)


def mirrored_point(point) -> glm.vec3:
    """``point``'s image in the mirror's plane."""
    normal = MIRROR_TURN * glm.vec3(0.0, 0.0, 1.0)
    return glm.vec3(point) - 2.0 * glm.dot(glm.vec3(point) - MIRROR_AT, normal) * normal


IMAGE_EYE = mirrored_point(CAMERA_EYE)


def before_portal_a(point) -> glm.vec3:
    """The point before portal A that the pair carries to ``point`` before B (B's local (x, y, z)
    is A's (-x, y, -z): spawn_portal_pair)."""
    half_turn = glm.angleAxis(glm.radians(180.0), glm.vec3(0.0, 1.0, 0.0))
    at_a = glm.translate(PORTAL_A) * glm.mat4_cast(PORTAL_A_TURN) * glm.mat4_cast(half_turn)
    return glm.vec3(at_a * glm.inverse(glm.translate(MIRROR_AT) * glm.mat4_cast(MIRROR_TURN)) * glm.vec4(point, 1.0))


def seen_object_scene(world, material: dict, mesh=None, turn=None) -> int:
    """At SEEN: a ball of ``Material(**material)`` (or ``mesh``, turned by ``turn``) before a grey
    wall, under a sky with some shape and a lamp between it and the mirror's image eye, up and
    to the side."""
    towards = glm.normalize(IMAGE_EYE - SEEN)
    across = glm.normalize(glm.cross(towards, glm.vec3(0.0, 1.0, 0.0)))
    world.spawn(Skybox(faces=SKY))
    world.spawn(Transform(position=SEEN - towards * 3.0, rotation=look_rotation(-towards)),
                MeshRef(quad(40.0, 40.0)), Material(color=(0.15, 0.15, 0.15, 1.0)))
    world.spawn(Transform(position=SEEN + towards * 1.6 + across * 0.9 + glm.vec3(0.0, 0.9, 0.0)),
                PointLight(intensity=12.0, range=20.0))
    shape = mesh if mesh is not None else sphere(0.8, 32, 16)
    return world.spawn(Transform(position=SEEN, rotation=turn or glm.quat()), MeshRef(shape), Material(**material))


def _linear_frame(scene, build, size, path):
    """The second frame of ``build``'s world (linear, antialiasing off) and its runner."""
    runner = scene(build, size)
    runner.engine.renderer.antialias = "off"
    runner.engine.reflection_system.path = path
    runner.frame()
    return srgb_to_linear(runner.frame()), runner


def from_its_eye(scene, content, *, path="per_mirror", size=EYE_SIZE) -> np.ndarray:
    """What ``content(world)`` spawns, seen directly from IMAGE_EYE looking at MIRROR_AT."""
    def direct(world):
        look_from(world, tuple(IMAGE_EYE), tuple(MIRROR_AT), fov=EYE_FOV)
        content(world)
    return _linear_frame(scene, direct, size, path)[0]


def through_a_reflection_and_from_its_eye(scene, content, way, *, path="per_mirror", size=EYE_SIZE, margin=2):
    """What ``content(world)`` spawns, rendered through ``way`` ("mirror": from CAMERA_EYE;
    "portal": from the point before A carried to IMAGE_EYE) by the reflection ``path``, and
    directly from IMAGE_EYE (looking at MIRROR_AT) in a world with neither, turned left for right
    for a mirror; linear images, the pixels at least ``margin`` in from the mirror's or
    portal A's outline (by the surface ids), and the reflection's runner."""
    names: dict = {}

    def reflected(world):
        if way == "mirror":
            look_from(world, tuple(CAMERA_EYE), tuple(MIRROR_AT), fov=EYE_FOV)
            names["surface"] = world.spawn(Transform(position=MIRROR_AT, rotation=MIRROR_TURN),
                                           MeshRef(quad(*MIRROR_SIZE)), Mirror())
        else:
            from engine.assets.portals import spawn_portal_pair
            look_from(world, tuple(before_portal_a(IMAGE_EYE)), tuple(PORTAL_A), fov=EYE_FOV)
            names["surface"], _ = spawn_portal_pair(world, PORTAL_A, PORTAL_A_TURN, MIRROR_AT, MIRROR_TURN,
                                                    size=MIRROR_SIZE)
        content(world)

    shown, runner = _linear_frame(scene, reflected, size, path)
    direct = from_its_eye(scene, content, path=path, size=size)
    assert runner.stats.reflection_views >= 1 and runner.stats.reflection_path == path
    inside = runner.engine.renderer.targets.read_surface_ids() == names["surface"]
    for _ in range(margin):
        shrunk = inside.copy()
        shrunk[1:, :] &= inside[:-1, :]
        shrunk[:-1, :] &= inside[1:, :]
        shrunk[:, 1:] &= inside[:, :-1]
        shrunk[:, :-1] &= inside[:, 1:]
        inside = shrunk
    assert inside.mean() > 0.5, inside.mean()
    return shown, direct[:, ::-1] if way == "mirror" else direct, inside, runner


def assert_shown_as_from_its_eye(scene, material: dict, bare: dict, way: str, *, path="per_mirror",
                                 mesh=None, turn=None, extra=None, changed: int = 40, by: float = 0.05,
                                 at_most=(0.01, 0.04)) -> None:
    """The ball at SEEN of ``material`` (Material's fields; out of the camera's sight) through
    ``way`` is the frame from the reflection's own eye, pixel by pixel (the 99th percentile and
    largest difference of a channel within ``at_most``), and the feature is there: at least
    ``changed`` of those pixels differ by ``by`` from the ``bare`` material's frame from that eye.
    ``mesh`` and ``turn``: another object than the ball; ``extra(world)`` adds to the scene."""
    def content(chosen):
        def build(world):
            seen_object_scene(world, chosen, mesh, turn)
            if extra is not None:
                extra(world)
        return build

    shown, direct, inside, runner = through_a_reflection_and_from_its_eye(scene, content(material), way, path=path)
    assert not (0 <= runner.project(SEEN)[0] < runner.size[0])   # (out of the camera's own sight)
    without = from_its_eye(scene, content(bare), path=path)
    if way == "mirror":
        without = without[:, ::-1]
    there = np.abs(shown - without).max(axis=-1)[inside]
    assert (there > by).sum() >= changed, (there > by).sum()
    apart = np.abs(shown - direct).max(axis=-1)[inside]
    assert np.quantile(apart, 0.99) <= at_most[0] and apart.max() <= at_most[1], (np.quantile(apart, 0.99),
                                                                                    apart.max())


@pytest.mark.parametrize("way, path", [("mirror", "per_mirror"), ("portal", "per_mirror"), ("mirror", "batched"),
                                       ("portal", "batched")])
def test_a_coat_in_a_mirror_and_through_a_portal_is_shaded_from_that_views_eye(scene, way, path):
    """A coated red ball off to the camera's right, seen only in a mirror (or through a portal):
    its coat's highlight and its sky reflection, Fresnel and all, are the frame a camera at the
    mirror's image eye (the eye carried through the portal) draws of it, turned left for right for
    the mirror, by either reflection path; and the coat is there (the bare ball's frame differs)."""
    base = dict(color=(0.5, 0.08, 0.05, 1.0), roughness=0.9, environment_reflection=0.0)
    assert_shown_as_from_its_eye(scene, dict(base, clearcoat=1.0, clearcoat_roughness=0.15), base, way, path=path)


# A probe face is shaded from the probe's centre: a ball off the probe's +X face, the face
# against a camera standing at the probe's centre looking +x (90 degrees, square).
PROBE_BALL = glm.vec3(2.6, 0.2, 0.4)
PROBE_SIZE = 32


def probe_face_and_from_its_centre(scene, material: dict) -> tuple[np.ndarray, np.ndarray]:
    """Face +X of a probe at the origin (six-pass capture, the ball of ``material`` before a wall
    and a lamp, under the sky with some shape) and, texel by texel, the pixel of a camera at
    the probe's centre looking +x whose ray is the texel's direction; both linear.  The main
    camera stands 6 m back, looking away."""
    from components import ReflectionProbe
    from engine.core.cube_faces import face_directions

    def content(world):
        world.spawn(Skybox(faces=SKY))
        world.spawn(Transform(position=(7.0, 0.0, 0.0), rotation=look_rotation(glm.vec3(1.0, 0.0, 0.0))),
                    MeshRef(quad(30.0, 30.0)), Material(color=(0.15, 0.15, 0.15, 1.0)))
        world.spawn(Transform(position=(1.2, 1.2, 1.3)), PointLight(intensity=10.0, range=20.0))
        world.spawn(Transform(position=PROBE_BALL), MeshRef(sphere(0.8, 32, 16)), Material(**material))

    def probed(world):
        look_from(world, (0.0, 0.0, 6.0), (-3.0, 0.0, 6.0), fov=EYE_FOV)
        world.probe = world.spawn(Transform(), ReflectionProbe(resolution=PROBE_SIZE, refresh="once"))
        content(world)

    def direct(world):
        look_from(world, (0.0, 0.0, 0.0), (1.0, 0.0, 0.0), fov=90.0)
        content(world)

    runner = scene(probed, (16, 16))
    runner.engine.stages["probes"].path = "six_pass"
    runner.frame()
    assert runner.stats.probe_faces == 6 and runner.stats.probe_path == "six_pass"
    face = runner.engine.renderer.probes.read_face(runner.world.probe, 0).astype(np.float64)
    seen, camera = _linear_frame(scene, direct, (PROBE_SIZE, PROBE_SIZE), "per_mirror")
    _, rays = pixel_rays(camera.engine.main_view, (PROBE_SIZE, PROBE_SIZE))
    nearest = np.argmax(face_directions(0, PROBE_SIZE).reshape(-1, 3) @ rays.reshape(-1, 3).T, axis=1)
    return face, seen.reshape(-1, 3)[nearest].reshape(face.shape)


def assert_probe_face_as_from_its_centre(scene, material: dict, bare: dict, *, changed: int = 20,
                                         by: float = 0.05) -> None:
    """The probe's face showing the ball of ``material`` is the frame from the probe's centre
    (linear, the face's float against the frame's 8 bits: within 0.01, 99th percentile, and
    0.04), and the feature is there: ``changed`` texels differ by ``by`` from ``bare``'s face."""
    face, seen = probe_face_and_from_its_centre(scene, material)
    without, _ = probe_face_and_from_its_centre(scene, bare)
    there = np.abs(np.clip(face, 0.0, 1.0) - np.clip(without, 0.0, 1.0)).max(axis=-1)
    assert (there > by).sum() >= changed, (there > by).sum()
    apart = np.abs(np.clip(face, 0.0, 1.0) - seen).max(axis=-1)
    assert np.quantile(apart, 0.99) <= 0.01 and apart.max() <= 0.04, (np.quantile(apart, 0.99), apart.max())


def test_a_coat_in_a_probe_face_is_shaded_from_the_probes_centre(scene):
    """A coated red ball off a probe's +X face: the face shows it (its coat's highlight, its sky
    reflection and Fresnel) as a camera at the probe's centre looking that way does, texel by
    texel; and the coat is there (the bare ball's face differs)."""
    base = dict(color=(0.5, 0.08, 0.05, 1.0), roughness=0.9, environment_reflection=0.0)
    assert_probe_face_as_from_its_centre(scene, dict(base, clearcoat=1.0, clearcoat_roughness=0.15), base)
