"""The array planner of a reflection level (engine/render/view_plan.py) against a second
path: each view's camera worked out one at a time with glm from its parent (the carried
view matrix, its eye, Lengyel's oblique projection from engine.core.reflection_math), and
the cull's rectangles against the surfaces' corners projected one by one."""
from __future__ import annotations

import numpy as np
import pytest
from pyglm import glm

import engine.render.plan_rows as plan_rows
import engine.render.view_plan as view_plan
import engine.render.view_tree as view_tree
from components.limits import VIEW_DIRECT, VIEW_MIRROR, VIEW_PORTAL
from engine.core.reflection_math import oblique_is_safe, oblique_projection, signed_distance, transform_plane
from engine.render.batched_mirrors import views_block
from engine.render.end_images import EndImages
from engine.render.views import PlannedView, View
from tests import golden
from tests.golden_scenes import cases

SCENES = ("hall_start", "hall_mirror_wall", "hall_tunnel", "mirror_ring_16", "portals_depth_8")


def _reference(parent: View, state, root: View, node: View) -> View:
    """The view through ``state`` from ``parent``, one glm call at a time."""
    eye = glm.vec3(state.carry * glm.vec4(parent.eye, 1.0))
    view = parent.view * glm.inverse(state.carry)
    proj = root.proj
    near = root.proj[3][2] / (root.proj[2][2] - 1.0)
    if oblique_is_safe(eye, state.exit_plane, near):
        proj = oblique_projection(root.proj, transform_plane(view, state.exit_plane))
    # Through a surface a view is no longer direct; it is a mirror's or a portal's, on top of
    # the kinds its chain passed, and shows the layers both it and the surface show.
    kinds = (parent.kinds & ~VIEW_DIRECT) | (VIEW_MIRROR if state.kind == "mirror" else VIEW_PORTAL)
    return View(view=view, proj=proj, eye=eye, size=node.size, clip_plane=state.exit_plane,
                mirrored=parent.mirrored != (state.kind == "mirror"), scissor=node.scissor, node=node.node,
                skip=state.exit_entity, hide=parent.hide, kinds=kinds, layers=parent.layers & state.layers)


def batched_row(view: View) -> np.ndarray:
    """The Views block row of ``view`` from its glm matrices and fields, one at a time (the
    layout of shaders/include/views_block.glsl's MirrorView)."""
    width, height = view.size
    x, y, w, h = view.scissor if view.scissor is not None else (0, 0, width, height)
    row = np.zeros(32, np.float32)
    row[0:16] = np.frombuffer(view.view_proj.to_bytes(), np.float32)
    row[16:20] = tuple(view.clip_plane)
    scale = glm.length(glm.vec3(view.view[0]))   # the way scale (view_axis.glsl), negative where mirrored
    row[20:24] = (*view.eye, -scale if view.mirrored else scale)
    row[24:28] = (2.0 * x / width - 1.0, 2.0 * y / height - 1.0,
                  2.0 * (x + w) / width - 1.0, 2.0 * (y + h) / height - 1.0)
    row[28:32].view(np.uint32)[:] = (view.node, view.skip, view.hide, view.view_mask)
    return row


def test_the_views_block_holds_each_views_row_then_zeros():
    """A level's Views block (packed from the views' Camera blocks in arrays) is the count,
    then each view's row as glm computes it one view at a time, then zeros."""
    views = []
    for i in range(5):
        eye = glm.vec3(i, 1.0 + i, 4.0 - i)
        view = View(glm.lookAt(eye, glm.vec3(0.0, 0.5 * i, 0.0), glm.vec3(0, 1, 0)),
                    glm.perspective(glm.radians(50.0 + i), 16 / 9, 0.1, 80.0), eye, (320, 180),
                    clip_plane=glm.vec4(0.0, 1.0, 0.1 * i, -0.5), mirrored=i % 2 == 1,
                    scissor=None if i == 0 else (10 * i, 5 * i, 100 + i, 60 - i), node=3 + i, skip=40 + i,
                    hide=i, kinds=VIEW_MIRROR if i % 2 else VIEW_PORTAL, layers=0xF0F >> i)
        views.append(view)
    block = np.frombuffer(views_block(views), np.float32)
    assert block[0:4].view(np.int32).tolist() == [5, 0, 0, 0]
    for i, view in enumerate(views):
        got = block[4 + 32 * i: 4 + 32 * (i + 1)]
        assert np.allclose(got[:28], batched_row(view)[:28], rtol=1e-6, atol=1e-6), f"view {i}"
        assert np.array_equal(got[28:].view(np.uint32), batched_row(view)[28:].view(np.uint32)), f"view {i} ids"
    assert not block[4 + 32 * 5:].any()
    assert np.frombuffer(views_block([]), np.int32)[0] == 0
    with pytest.raises(ValueError, match="at most"):
        views_block(views * 7)


@pytest.fixture
def trees(monkeypatch):
    """Every TreeResult the next frames render, with its root."""
    rendered = []
    render = view_tree.ViewTree.render

    def recording(self, root, levels, surfaces, *settings):
        result = render(self, root, levels, surfaces, *settings)
        rendered.append((root, result))
        return result
    monkeypatch.setattr(view_tree.ViewTree, "render", recording)
    return rendered


@pytest.mark.parametrize("name", SCENES)
def test_planned_views_equal_the_one_at_a_time_views(ctx, trees, name):
    """Camera blocks and batched rows of every planned view agree with glm's to float32
    precision, across mirrors, portals and depth-8 recursion (each view from its planned
    parent, so an error cannot hide in a chain)."""
    golden.render_case(ctx, {case.name: case for case in cases()}[name])
    views = [(root, node) for root, result in trees for node in result.views[1:]]
    assert len(views) >= 8, f"{name}: the scene made only {len(views)} reflection views"
    if name.startswith("hall"):  # the probes' faces are roots planned the same way (issue 25 item 4)
        assert sum(len(result.views) - 1 for root, result in trees if root.name.startswith("probe face")) >= 8
    for root, node in views:
        assert isinstance(node.view, PlannedView)
        expected = _reference(node.parent.view, node.surface, root, node.view)
        got = np.frombuffer(node.view.camera_block(), np.float32)
        want = np.frombuffer(expected.camera_block(), np.float32)
        assert np.array_equal(got[76:], want[76:]), f"{name} view {node.index}: ids differ"
        assert np.allclose(got[:76], want[:76], rtol=2e-3, atol=2e-4), \
            f"{name} view {node.index} (level {node.level}): worst {np.abs(got[:76] - want[:76]).max()}"
        row = np.frombuffer(views_block([node.view]), np.float32)[4:36]  # the batched path's row, from the planned view
        want_row = batched_row(expected)
        assert np.allclose(row, want_row, rtol=2e-3, atol=2e-4), f"{name} view {node.index}: batched row"
        assert node.view.mirrored == expected.mirrored
        assert node.view.name == f"{node.surface.kind} {node.surface.entity}"
        # The matrices read back from the block are the view's.
        assert np.allclose(np.array(node.view.view.to_list()), np.array(expected.view.to_list()), atol=2e-4)
        assert glm.distance(node.view.eye, expected.eye) < 1e-3


@pytest.mark.parametrize("name", ("hall_start", "mirror_ring_16"))
def test_every_view_shows_inside_its_rectangle_and_faces_its_parent(ctx, trees, name):
    """The cull's facts, from the surfaces' own corners: a view's surface faces its parent's
    eye, and every corner of it that is in front of the parent's eye projects inside the
    view's rectangle (with the rectangle's 1-pixel margin) or the rectangle is clipped by
    the parent's own."""
    golden.render_case(ctx, {case.name: case for case in cases()}[name])
    checked = 0
    for root, result in trees:
        for node in result.views[1:]:
            parent = node.parent
            assert signed_distance(node.surface.plane, parent.view.eye) > 0.0
            x, y, w, h = node.rect
            px, py, pw, ph = parent.rect
            assert px <= x and py <= y and x + w <= px + pw and y + h <= py + ph
            vp = root.proj * parent.view.view
            for corner in node.surface.corners:
                clip = vp * glm.vec4(*map(float, corner))
                if clip.w <= 1e-3 or any(abs(c) > clip.w for c in (clip.x, clip.y, clip.z)):
                    continue  # behind the eye or outside the frustum: the rectangle is clipped there
                sx = (clip.x / clip.w + 1.0) * 0.5 * root.size[0]
                sy = (clip.y / clip.w + 1.0) * 0.5 * root.size[1]
                inside_parent = px <= sx <= px + pw and py <= sy <= py + ph
                if inside_parent:
                    assert x - 1e-3 <= sx <= x + w + 1e-3 and y - 1e-3 <= sy <= y + h + 1e-3, \
                        f"{name} view {node.index}: corner at {sx:.1f}, {sy:.1f} outside {node.rect}"
                    checked += 1
    assert checked >= 20


def test_the_surfaces_and_their_arrays_are_kept_while_no_surface_changes(scene):
    """The planner's arrays are built once while the mirrors and portals stand still (a
    moving camera or box changes nothing), and made again when one moves or changes."""
    import math

    from components import Material, MeshRef, Mirror, Transform
    from engine.assets.mesh import box, quad
    from engine.assets.portals import spawn_portal_pair
    from engine.render.surface_table import PlannerSurfaces
    from engine.resources import Surfaces
    from tests.support import look_from

    ents = {}

    def build(world):
        look_from(world, (0.0, 1.5, 4.0), target=(0.0, 1.5, -2.0))
        ents["mirror"] = world.spawn(Transform(position=(-1.5, 1.5, -2.0)), MeshRef(quad(2.0, 2.0)),
                                     Material(), Mirror())
        ents["box"] = world.spawn(Transform(position=(0.0, 0.5, 0.0)), MeshRef(box()), Material())
        ents["a"], ents["b"] = spawn_portal_pair(world, (1.5, 1.5, -2.0), None, (6.0, 1.5, 0.0),
                                                 glm.angleAxis(math.pi / 2, glm.vec3(0, 1, 0)))
    runner = scene(build, (96, 64))
    runner.frame()
    surfaces = runner.world.resources[Surfaces]
    table = runner.world.resources[PlannerSurfaces].table  # the reflect stage's, made from them
    runner.world.get(ents["box"], Transform).position = glm.vec3(0.3, 0.5, 0.0)
    runner.frame()
    assert runner.world.resources[Surfaces] is surfaces and runner.world.resources[PlannerSurfaces].table is table
    runner.world.get(ents["b"], Transform).position = glm.vec3(6.0, 1.6, 0.0)  # a portal's partner moves
    runner.frame()
    moved = runner.world.resources[Surfaces]
    assert moved is not surfaces and moved.portals[ents["a"]].carry != surfaces.portals[ents["a"]].carry
    runner.frame()
    assert runner.world.resources[Surfaces] is moved
    runner.world.get(ents["mirror"], Mirror).reflect_rate = 0.5
    runner.frame()
    assert runner.world.resources[Surfaces] is not moved
    assert runner.world.resources[Surfaces].mirrors[ents["mirror"]].reflect_rate == 0.5


def test_an_end_view_repeats_the_view_that_saw_its_surface_last_up_its_chain(ctx, trees, monkeypatch):
    """The view tree finds each end view's ancestor in arrays (the index of the view that saw
    each surface last, carried a level at a time): the matrix it hands the end-image pass is
    the one a walk up the end view's chain gives (the view that looked into the same surface
    last, times the surface's carry inverted)."""
    drawn = []
    draw = EndImages.draw

    def recording(self, views, surfaces, to_ancestors, targets, root):
        drawn.extend(zip(views, surfaces, to_ancestors, strict=True))
        return draw(self, views, surfaces, to_ancestors, targets, root)
    monkeypatch.setattr(EndImages, "draw", recording)
    golden.render_case(ctx, {case.name: case for case in cases()}["hall_start"])
    nodes = {id(node.view): node for _, result in trees for node in result.end_views}
    assert len(drawn) >= 1 and len(nodes) == len(drawn)
    for view, entity, matrix in drawn:
        node = nodes[id(view)]
        assert node.surface.entity == entity
        seer = node.parent
        while seer.surface is None or seer.surface.entity != entity:
            seer = seer.parent
            assert seer is not None, "an end view without its surface up its chain was drawn"
        assert matrix == seer.parent.view.view * glm.inverse(node.surface.carry)


def test_a_surface_with_eight_corners_is_culled_on_all_of_them():
    """A mirror whose mesh has some thickness has 8 distinct box corners, and a side culls
    the pair only when every one of them is outside it.  Two thick mirrors facing each
    other, seen by cameras where only the far four corners of one show (the near four are
    behind the camera's near plane or off one side): the first level's candidates are the
    surfaces that face the eye and have, for every side of the frustum, a corner inside it
    (worked out here corner by corner in glm), and a cull on either face's four alone would
    differ for one of the cameras (so the other four are what keeps it)."""
    from engine.core.reflection_math import reflection_matrix
    from engine.resources import SurfaceState

    def thick_mirror(entity: int, z: float, facing: float) -> SurfaceState:
        plane = glm.vec4(0.0, 0.0, facing, -facing * z)
        corners = np.array([(x, y, z + dz, 1.0) for x in (-1.0, 1.0) for y in (0.0, 2.0) for dz in (-0.05, 0.05)])
        return SurfaceState(entity, "mirror", plane, corners, None, reflection_matrix(plane), plane, entity, 2)

    def kept(state: SurfaceState, view: View, corners) -> bool:
        if glm.dot(glm.vec4(view.eye, 1.0), state.plane) <= 0.0:
            return False
        clips = [view.proj * view.view * glm.vec4(*map(float, corner)) for corner in corners]
        sides = [lambda c: c.x - c.w, lambda c: c.y - c.w, lambda c: c.z - c.w,
                 lambda c: -c.x - c.w, lambda c: -c.y - c.w, lambda c: -c.z - c.w]
        return all(min(side(c) for c in clips) < 0.0 for side in sides)

    states = [thick_mirror(7, 0.0, 1.0), thick_mirror(8, 6.0, -1.0)]
    table = view_plan.SurfaceTable(states)
    assert table.corner_count == 8
    proj = glm.perspective(glm.radians(60.0), 16 / 9, 0.1, 50.0)
    one_face_differs = False
    for eye, target in (((0.3, 1.0, 3.0), (0.0, 1.0, 0.0)), ((0.0, 1.0, 0.08), (0.0, 1.0, -1.0)),
                        ((2.2, 1.0, 3.0), (-1.0, 1.0, 1.0))):
        view = View(glm.lookAt(glm.vec3(eye), glm.vec3(target), glm.vec3(0, 1, 0)), proj, glm.vec3(eye), (320, 180))
        root_proj, inv_root_proj = view_plan._mat(proj), view_plan._mat(glm.inverse(proj))
        candidates, _ = table.plan(plan_rows.LevelRows.root(view), 1, view, root_proj, inv_root_proj, 1, 8, 0)
        planned = [] if candidates is None else candidates.surface.tolist()
        expected = [i for i, state in enumerate(states) if kept(state, view, state.corners)]
        assert planned and planned == expected, (eye, planned, expected)
        for i, state in enumerate(states):  # each face's four corners alone
            for dz in (-0.05, 0.05):
                face = [c for c in state.corners if np.isclose(c[2] - (0.0 if i == 0 else 6.0), dz)]
                one_face_differs |= kept(state, view, face) != (i in expected)
    assert one_face_differs


def test_a_level_planned_from_the_same_rows_is_found_again_read_only(scene, monkeypatch):
    """``SurfaceTable.plan`` keeps its plans: with the camera and the surfaces still (a box
    moving), the next frame computes no plan and draws the same image, with the views its
    levels made the frame before (``Candidates.derived``); a camera that moves, or a surface
    that moves (a new table), plans again, and a camera that moves every frame keeps no
    plan (nothing would find it again); a kept plan cannot be written."""
    from components import Material, MeshRef, Mirror, Transform
    from engine.assets.mesh import box, quad
    from engine.render.surface_table import PlannerSurfaces
    from tests.support import look_from
    from tests.test_mirrors import FACING_BACK, base_scene

    ents = {}

    def build(world):
        base_scene(world)  # a light and the sky
        ents["camera"] = look_from(world, (0.3, 1.5, 2.5), target=(0.0, 1.5, -2.0))
        # No end images: past the depth limit they repeat last frame's image, so still frames
        # would still differ for a few frames.
        ents["front"] = world.spawn(Transform(position=(0.0, 1.5, -2.0)), MeshRef(quad(3.0, 2.0)), Material(),
                                    Mirror(end_image=False))
        ents["back"] = world.spawn(Transform(position=(0.0, 1.5, 4.0), rotation=FACING_BACK), MeshRef(quad(3.0, 2.0)),
                                   Material(), Mirror(end_image=False))
        ents["box"] = world.spawn(Transform(position=(0.8, 0.5, 0.0)), MeshRef(box()), Material(color=(0.9, 0.2, 0.1)))
    computed = []
    plan, chain = view_plan.SurfaceTable._plan, view_plan.SurfaceTable.plan_chain

    def counting(self, *args, **kwargs):
        computed.append(args[1])  # the depth
        return plan(self, *args, **kwargs)

    chained = []  # the levels planned in one run

    def counting_chain(self, *args, **kwargs):  # the levels of one view each, planned in one run
        levels = chain(self, *args, **kwargs)
        computed.extend(range(args[1] + 1, args[1] + 1 + len(levels)))
        chained.extend(range(args[1] + 1, args[1] + 1 + len(levels)))
        return levels
    monkeypatch.setattr(view_plan.SurfaceTable, "_plan", counting)
    monkeypatch.setattr(view_plan.SurfaceTable, "plan_chain", counting_chain)
    runner = scene(build, (96, 64))
    # The planner's own keeping, on frames that draw the tree: a still frame would keep the
    # whole tree and plan nothing (ReflectionSystem.keep_still_views, tests/test_kept_views.py).
    runner.engine.reflection_system.keep_still_views = False
    runner.frame()
    first = runner.frame()
    assert runner.stats.reflection_views >= 3 and computed  # mirror in mirror in mirror
    computed.clear()
    views_before = [node.view for node in runner.engine.reflection_system.views[1:]]
    again = runner.frame()
    assert computed == [] and np.array_equal(first, again)
    # The same views (a View is not changed once made), in new nodes of this frame's tree.
    views = runner.engine.reflection_system.views[1:]
    assert [node.view for node in views] == views_before and len(views) >= 3
    assert all(a is b for a, b in zip((node.view for node in views), views_before, strict=True))
    # A kept plan is shared by the frames that find it: its arrays are read-only.
    table = runner.world.resources[PlannerSurfaces].table
    kept = next(candidates for _, (candidates, _) in table._plans.values() if candidates is not None)
    with pytest.raises(ValueError, match="read-only"):
        kept.blocks[0, 0] = 1.0
    # Something that is not a surface moves: the plans hold (the image changes where the box is).
    runner.world.get(ents["box"], Transform).position = glm.vec3(-0.8, 0.5, 0.0)
    moved_box = runner.frame()
    assert computed == [] and not np.array_equal(moved_box, again)
    # The camera moves: every level is planned again, and kept only from the second frame
    # it stands there; a camera moving every frame keeps none.
    kept_plans = len(table._plans)
    for step in range(3):
        runner.world.get(ents["camera"], Transform).position = glm.vec3(0.4 + 0.01 * step, 1.5, 2.5)
        moving = runner.frame()
        assert computed and computed[0] == 1 and len(table._plans) == kept_plans
        computed.clear()
    assert np.array_equal(runner.frame(), moving) and computed and len(table._plans) > kept_plans  # kept now
    computed.clear()
    assert np.array_equal(runner.frame(), moving) and computed == []  # and found
    # A camera going back and forth (a loop: each frame where it stood two frames before)
    # moves every frame: it keeps no plan, and its pair is planned in one run each frame;
    # a kept row's levels were planned one by one, and a loop longer than the plans kept
    # found none of them again.
    kept_plans = len(table._plans)
    frames = []
    for step in range(5):
        runner.world.get(ents["camera"], Transform).position = glm.vec3(0.6 if step % 2 else 0.5, 1.5, 2.5)
        computed.clear()
        chained.clear()
        frames.append(runner.frame())
        assert computed and len(table._plans) == kept_plans, step
        assert step == 0 or len(chained) >= 2, (step, chained)
    assert np.array_equal(frames[0], frames[2]) and np.array_equal(frames[1], frames[3])
    assert not np.array_equal(frames[0], frames[1])
    # A mirror moves: a new table, planned afresh.
    runner.world.get(ents["back"], Transform).position = glm.vec3(0.0, 1.5, 4.2)
    runner.frame()
    assert computed and runner.world.resources[PlannerSurfaces].table is not table
