"""Level files: a level as TOML a person can edit, loaded into a world and saved back.

A level file has ``[level]`` (``name``, optional ``game``), an optional free-form ``[rules]``
table the game reads, and ``[[entity]]`` tables: a unique ``name`` and one table per
component, named by its class (``[entity.Transform]``) with the component's fields.
Vectors and colours are lists, a rotation is a quaternion ``[w, x, y, z]`` or
``{ yaw = .., pitch = .. }`` (degrees) or ``{ look = [x, y, z] }``; a mesh is a generator
(``{ box = [w, h, d] }``, ``{ quad = [w, h] }``, ``{ plane = [w, d], uv_repeat = r }``,
``{ sphere = r }``) or ``{ file = "x.obj" }``; a texture (``Material.texture``, ``normal_map``,
``emissive_map``, ``metallic_roughness_map``, ``occlusion_map``, ``lightmap``) ``{ checker = [size, squares] }``,
``{ ripples = [size, rings] }`` (a normal map) or ``{ file = "x.png" }``; paths are relative
to the level file and stay inside its folder (or an asset root: ``LevelGame.asset_roots``,
``--asset-root DIR``). Entity references
(``Transform.parent``, ``Portal.partner``) are entity names. docs/level_files.md has the
whole format with an example.

Loading checks everything before anything is made (``load_level``): a mistake is a
``LevelError`` naming the file, the line, the entity and the field. A level is data a stranger
may have written: whatever file it names (a symlink loop, a FIFO, a device, an image bomb, a
file nested past any parser's depth, a path outside its folder), loading ends in the level or
in a LevelError, within ``LEVEL_MEMORY_BUDGET``. ``Level.spawn`` then
creates the entities all or nothing. The same asset file (and the same generated mesh or
texture) loaded twice is one object, so the renderer uploads it once.

This module is the level file's public face: ``LevelGame``, and ``load_level``, ``Level``,
``LevelError`` and ``save_level`` re-exported from where they live, as games and users
import them (the memory budget is a setting of the module that counts it:
``engine.assets.level_assets.LEVEL_MEMORY_BUDGET``). Each job has its own module:

- engine.assets.level_read: reading and checking a file (``load_level``, ``Level``,
  ``LevelError``, ``ENGINE_COMPONENTS``: the components a file may hold);
- engine.assets.level_lines: the line of each entity, table and field in the text (for
  the errors' line numbers), and the nesting limit;
- engine.assets.level_assets: the meshes and textures a level names, its asset roots
  (``set_asset_roots``) and its memory budget;
- engine.assets.level_save: writing a world back (``save_level``), keeping the file's own
  layout and comments.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

from engine.assets.level_read import Level as Level
from engine.assets.level_read import LevelError as LevelError
from engine.assets.level_read import load_level as load_level
from engine.assets.level_read import other_game_refusal
from engine.assets.level_save import save_level as save_level
from engine.core.game import Game
from engine.core.world import World


class LevelGame(Game):
    """A game that builds its world from a level file (``--level FILE`` replaces it).

    ``components``: the game's own plain-data components its files may hold, by name.
    ``asset_roots``: folders besides a level's own its files may name (shared game assets).
    ``game``: the name a level's ``[level] game`` gives this game; a level for another game
    is refused (one that names no game plays in any).  ``makes_camera``: the game adds the
    player's camera itself; otherwise a level with no camera is refused (its frames would
    be black).  After ``build``: ``level`` (the checked file) and ``names`` (entity ids by name)."""

    components: Mapping[str, type] = {}
    asset_roots: Sequence[str | Path] = ()
    game: str | None = None
    makes_camera: bool = False

    def __init__(self, level_path: str | Path) -> None:
        self.level_path = Path(level_path)
        self.level: Level | None = None
        self.names: dict[str, int] = {}

    def load(self) -> Level:
        """The game's level file, loaded and checked for this game (``check_level``)."""
        level = load_level(self.level_path, self.components, self.asset_roots, for_game=self.game)
        self.check_level(level)
        return level

    def check_level(self, level: Level) -> None:
        """A LevelError (naming the file) for a level made for another game, or one with no
        camera where the game makes none."""
        if self.game is not None and level.game is not None and level.game != self.game:
            raise LevelError(level.path, other_game_refusal(level.game, self.game), level._lines.get(("level", "game")))
        if not self.makes_camera and not level.has_camera:
            raise LevelError(level.path, "no entity has a Camera and a Transform, so every frame would be black (add "
                                         "one: [[entity]] with [entity.Transform] and [entity.Camera])")

    def build(self, world: World) -> None:
        self.level = self.load()
        self.names = self.level.spawn(world)

    def needs(self, world: World, entity: int, component: str | None = None) -> str | None:
        """Why the game cannot run without ``entity`` (``component`` None) or without that
        component of it, in words the level editor shows when it refuses to delete or remove
        it; None: the game does without it.  A game whose systems hold entities from its
        build (its laser, its solids) says so here, components and all.

        The default keeps what the level's ``[rules]`` name: an entity whose name is a rule's
        value (or in a rule's list or table) cannot be deleted, since a game reads its rules
        to find the entities it holds (an exit, a source, a target), and deleting one would
        fail inside the next frame; its components are the game's to guard."""
        if component is not None or self.level is None:
            return None
        for rule, value in self.level.rules.items():
            for name in _names_in(value):
                if self.names.get(name) == entity:
                    game = self.game or type(self).__name__
                    return f"{game} cannot do without it: the level's rules name it ({rule} = {name!r})"
        return None


def _names_in(value: object) -> list[str]:
    """The strings in a rule's value: itself, or those in its lists and tables, however
    deeply nested (walked with a stack, not recursion)."""
    found, stack = [], [value]
    while stack:
        item = stack.pop()
        if isinstance(item, str):
            found.append(item)
        elif isinstance(item, dict):
            stack.extend(item.values())
        elif isinstance(item, (list, tuple)):
            stack.extend(item)
    return found
