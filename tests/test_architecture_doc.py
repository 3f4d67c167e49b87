"""ARCHITECTURE.md stays true: its stage table is ``FRAME_STAGES`` in order and the frame
as ``Engine.schedule`` runs it (the sample games' systems where the doc places them), every
path it names exists, and every module of the engine, the systems and the shell is on its
map (a new module is placed in the doc when it is made; a moved one is moved there too)."""
from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOC = (ROOT / "ARCHITECTURE.md").read_text()
MAPPED = ("engine", "systems", "shell")


def stage_table() -> list[tuple[str, str]]:
    """(stage, code cell) of each row of the table under the "| stage |" header."""
    rows, inside = [], False
    for line in DOC.splitlines():
        if line.startswith("| stage |"):
            inside = True
            continue
        if inside:
            if not line.startswith("|"):
                break
            cells = [cell.strip() for cell in line.strip("|").split("|")]
            if set(cells[0]) <= {"-", " "}:
                continue
            rows.append((cells[0].strip("`"), cells[-1]))
    return rows


def test_the_stage_table_is_the_frame_stages_in_order():
    from shell.app import FRAME_STAGES

    assert [stage for stage, _ in stage_table()] == [name for name, _ in FRAME_STAGES]


def test_every_path_the_doc_names_exists():
    named = set(re.findall(r"`((?:engine|systems|shell|components|shaders|games|tests|benchmarks|docs)"
                           r"/[\w./*]*)`", DOC))
    assert named, "the doc names no paths"
    missing = sorted(p for p in named if "*" not in p and not (ROOT / p.rstrip("/")).exists())
    assert not missing, f"ARCHITECTURE.md names paths that do not exist: {missing}"


def test_every_engine_system_and_shell_module_is_on_the_map():
    modules = sorted(str(path.relative_to(ROOT)) for package in MAPPED for path in (ROOT / package).rglob("*.py")
                     if path.name != "__init__.py")
    absent = [m for m in modules if f"`{m}`" not in DOC]
    assert not absent, f"modules ARCHITECTURE.md does not place: {absent}"


def _documented_order(game_system: str | None = None, after: str | None = None,
                      before: str | None = None) -> list[str]:
    """The frame as ARCHITECTURE.md tells it: the stage table in order, with a game system
    placed by the stage it runs after (or before), followed by ``transform_late`` where it
    runs between the transform stage and extract (what the doc's paragraph on a game's own
    systems says)."""
    order = [stage for stage, _ in stage_table()]
    if game_system is None:
        return order
    at = order.index(after) + 1 if after is not None else order.index(before)
    order.insert(at, game_system)
    if order.index("transform") < at < order.index("extract"):
        order.insert(at + 1, "transform_late")
    return order


def _run_order(engine) -> list[str]:
    """The order a frame runs the engine's systems in (each system's ``process`` recorded;
    ``transform_late`` runs the transform stage's work inside its own: the outermost counts)."""
    ran, inside = [], []
    for name, system in engine.schedule:
        process = system.process

        def recorded(*args, name=name, process=process, **kwargs):
            if not inside:
                ran.append(name)
            inside.append(name)
            try:
                return process(*args, **kwargs)
            finally:
                inside.pop()
        system.process = recorded
    engine.frame(1 / 60, None)
    return ran


def test_the_frame_order_engine_schedule_prints_is_the_documented_one(ctx):
    """``Engine.schedule`` (the frame as it runs, in the order a frame runs it) is the stage
    table for a game without systems of its own, and for the two sample games the order the
    doc gives their systems: mirror beam's beam after the stage it names (then
    ``transform_late``, the doc's rule for a system between transform and extract), portal
    run's body before the stage it names."""
    from engine.core.game import Game
    from games.mirror_beam import MirrorBeam
    from games.portal_run import PortalRun
    from shell.app import Engine

    class Empty(Game):
        title = "architecture: schedule"

        def build(self, world) -> None:
            pass

    beam = re.search(r"Mirror\s+beam\s+traces\s+its\s+beam\s+after\s+`(\w+)`", DOC)
    body = re.search(r"portal\s+run\s+steps\s+its\s+body\s+before\s+`(\w+)`", DOC)
    assert beam and body and "`transform_late`" in DOC, "the doc no longer places the sample games' systems"
    for game, documented in ((Empty(), _documented_order()),
                             (MirrorBeam(), _documented_order("beam", after=beam[1])),
                             (PortalRun(verbose=False), _documented_order("physics", before=body[1]))):
        engine = Engine(game, ctx)
        try:
            assert [name for name, _ in engine.schedule] == documented, type(game).__name__
            assert _run_order(engine) == documented, type(game).__name__
        finally:
            engine.close()
