"""The generated checker is drawn from its cells (scene.frag's CHECKER build): the same
board as its texture, crisp up close, grey far off (issue 26: the near checker floor was
a magnified texture, blurred with beaded edges)."""
from __future__ import annotations

import numpy as np

from components import DirectionalLight, Material, MeshRef, Skybox, Transform
from engine.assets.mesh import plane
from engine.assets.texture_data import TextureData, checker_texture
from engine.render.renderer import checker_look
from tests.support import look_from

SIZE = (320, 180)


def floor_scene(texture: TextureData, uv_repeat: float = 10.0):
    def build(world):
        world.spawn(Skybox())
        world.spawn(DirectionalLight(direction=(0.0, -1.0, 0.0), intensity=1.0))
        look_from(world, (0.0, 0.6, 4.0), target=(0.0, 0.0, 0.0), fov=60.0)
        world.spawn(Transform(), MeshRef(plane(40, 40, uv_repeat=uv_repeat)), Material(texture=texture, roughness=1.0))
    return build


def sampled(texture: TextureData) -> TextureData:
    """The same pixels with no generator recorded: drawn by sampling the texture."""
    return TextureData(texture.pixels.copy(), name="sampled " + texture.name)


def test_a_generated_checker_is_drawn_analytically_and_another_texture_is_not():
    board = checker_texture(256, 16, a=(200, 150, 60), b=(90, 50, 20))
    cells, even, odd = checker_look(board)
    assert cells == 16.0 and even[0] < odd[0]  # 16 squares: the top-left cell (colour a) sums odd
    assert checker_look(sampled(board)) is None
    assert checker_look(checker_texture(100, 8)) is None  # 12-texel cells and a narrower last one: sampled


def test_the_board_is_the_textures_board_crisp_near_and_grey_far(scene):
    board = checker_texture(256, 8)
    analytic = scene(floor_scene(board), SIZE)
    textured = scene(floor_scene(sampled(board)), SIZE)
    a, t = analytic.frame().astype(int), textured.frame().astype(int)
    assert analytic.engine.renderer.batches and all(b.checker for b in analytic.engine.renderer.batches.values())
    # Same cells, same colours: near the camera (bottom rows), away from the cells' edges
    # (where the texture's blur differs), the two frames agree.
    near = a[120:, :], t[120:, :]
    edges = np.abs(np.diff(near[1], axis=1)).max(axis=2)[:, :-1] > 3
    calm = ~(edges | np.roll(edges, 1, 1) | np.roll(edges, -1, 1) | np.roll(edges, 1, 0) | np.roll(edges, -1, 0))
    calm = np.pad(calm, ((0, 0), (0, 2)))[:, :near[0].shape[1]]
    diff = np.abs(near[0] - near[1]).max(axis=2)[calm]
    assert calm.sum() > 5000 and np.percentile(diff, 99) <= 6, (calm.sum(), np.percentile(diff, 99))
    # Crisp: along the bottom rows, a change between light and dark cells takes under two
    # pixels on average analytically (1.5 on llvmpipe and on an H200, whose bottom row alone
    # has a 3-pixel step); the magnified texture spreads it wider (2.5 on llvmpipe, 2.0 on
    # the H200).
    def transition_widths(row):
        luma = row.mean(axis=1)
        light, dark = luma.max(), luma.min()
        between = (luma > dark + 0.15 * (light - dark)) & (luma < light - 0.15 * (light - dark))
        runs, count = [], 0
        for inside in between:
            if inside:
                count += 1
            elif count:
                runs.append(count)
                count = 0
        return runs
    def mean_width(rows):
        widths = [width for row in rows for width in transition_widths(row)]
        return sum(widths) / len(widths)
    assert mean_width(a[-8:]) <= 1.75 and mean_width(a[-8:]) < mean_width(t[-8:]), \
        (mean_width(a[-8:]), mean_width(t[-8:]))
    # Far off (the rows just below the horizon, row 70 here), where cells are under a pixel:
    # both are the board's mean, evenly grey, with no pattern beating against the pixels.
    horizon = int(np.argmax(np.abs(np.diff(a[:, :, 2].mean(axis=1))) > 20))
    far_a, far_t = a[horizon + 2:horizon + 8], t[horizon + 2:horizon + 8]
    assert np.abs(far_a.mean(axis=(0, 1)) - far_t.mean(axis=(0, 1))).max() < 8
    assert far_a.std(axis=1).max() < 3, far_a.std(axis=1).max()  # the texture's rows: up to 20
