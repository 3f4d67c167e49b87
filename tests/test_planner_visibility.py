"""A mirror hidden by its own Visibility makes no view: the array planner (the one planner,
``SurfaceTable.plan``) makes no candidate for it (no claim, no query), not only the frame no
view (the claims' pixel counts drop a candidate that shows nothing, so a planner that
ignored the Visibility would still draw the right frame, one query dearer a level).

Each case must make the views worked out by hand: none into a mirror its parent view does
not draw (hidden in direct views, on a layer the camera does not show, hidden in mirrors),
and still the view into the mirror next to it, so an empty frame cannot pass."""
from __future__ import annotations

import pytest
from pyglm import glm

from components import Camera, DirectionalLight, Material, MeshRef, Mirror, Skybox, Transform, Visibility
from engine.assets.mesh import quad
from engine.render import view_plan
from tests.support import look_from
from tests.test_visibility import SIZE, in_surface, two_mirrors


def facing_pair(ents):
    """A front mirror the camera looks into and a back mirror behind the camera facing it:
    the back one is seen only in the front one (and so on, back and forth)."""
    def build(world):
        world.spawn(DirectionalLight(direction=(0.2, -1.0, -0.5), intensity=2.0))
        world.spawn(Skybox())
        look_from(world, (0.0, 1.5, 4.0), target=(0.0, 1.5, -2.0))
        ents["front"] = world.spawn(Transform(position=(0, 1.5, -2)), MeshRef(quad(4, 3)),
                                    Material(color=(0.1, 0.1, 0.1)), Mirror(max_depth=3, end_image=False))
        ents["back"] = world.spawn(Transform(position=(0, 1.5, 6), rotation=glm.angleAxis(glm.pi(), glm.vec3(0, 1, 0))),
                                   MeshRef(quad(4, 3)), Material(color=(0.1, 0.1, 0.1)),
                                   Mirror(max_depth=3, end_image=False))
    return build


# case -> (scene, the hidden mirror, its Visibility's fields, the camera's shown layers)
CASES = {
    "hidden_directly": (two_mirrors, "left", {"direct": False}, None),
    "on_a_layer_not_shown": (two_mirrors, "left", {"layers": [5]}, [0, 3]),
    "hidden_in_mirrors": (facing_pair, "back", {"in_mirrors": False}, None),
}


def _run(scene, monkeypatch, case: str, hidden: bool) -> tuple[list[tuple[int, ...]], set[int], dict, object]:
    """Two frames of ``case``: each view's chain of surfaces (entities, root first), the
    surfaces the planner made candidates of, the entities, and the runner; the planner's
    cull must have run."""
    with monkeypatch.context() as patch:  # each run wraps the planner's own methods, not the last run's wrappers
        return _frames(scene, patch, case, hidden)


def _frames(scene, monkeypatch, case: str, hidden: bool):
    build, name, visibility, layers = CASES[case]
    calls = {"cull": 0}
    cull = view_plan.SurfaceTable.cull

    def counting_cull(self, *args, **kwargs):
        if not kwargs.get("fallback"):  # the fallback's own cull (which surfaces lost their view) plans nothing
            calls["cull"] += 1
        return cull(self, *args, **kwargs)

    candidates = set()
    plan = view_plan.SurfaceTable.plan

    def recording_plan(self, *args, **kwargs):
        planned = plan(self, *args, **kwargs)
        if planned[0] is not None:
            candidates.update(self.entity_list[s] for s in planned[0].surface.tolist())
        return planned

    monkeypatch.setattr(view_plan.SurfaceTable, "cull", counting_cull)
    monkeypatch.setattr(view_plan.SurfaceTable, "plan", recording_plan)
    ents = {}
    runner = scene(build(ents), SIZE)
    if layers is not None:
        for _, camera in runner.world.query_one(Camera):
            camera.shows_layers = layers
    if hidden:
        runner.world.add_component(ents[name], Visibility(**visibility))
    runner.frame()
    runner.frame()
    assert calls["cull"] > 0, calls
    chains = []
    for node in runner.engine.reflection_system.views[1:]:
        chain = []
        while node is not None and node.surface is not None:
            chain.append(node.surface.entity)
            node = node.parent
        chains.append(tuple(reversed(chain)))
    return sorted(chains), candidates, ents, runner


@pytest.mark.parametrize("case", CASES)
def test_a_mirror_hidden_by_its_own_visibility_makes_no_view(scene, monkeypatch, case):
    _, name, _, _ = CASES[case]
    shown, planned, ents, _ = _run(scene, monkeypatch, case, hidden=False)
    mirror = ents[name]
    assert any(mirror in chain for chain in shown) and mirror in planned, shown  # looked into
    chains, planned, ents, runner = _run(scene, monkeypatch, case, hidden=True)
    mirror = ents[name]
    assert mirror not in planned, planned  # no candidate, so no claim
    assert chains and not any(mirror in chain for chain in chains), chains
    if case == "hidden_in_mirrors":  # seen directly, not in the front mirror: its one view
        assert chains == [(ents["front"],)], chains
    else:  # the other mirror's view stays; the hidden one is not drawn at all
        assert chains == [(ents["right"],)], chains
        assert not in_surface(runner, mirror).any()
        assert in_surface(runner, ents["right"]).sum() > 200
