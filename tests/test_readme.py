"""Every README code example runs: each ```python block as the program a reader would save
and run (headless, one frame), and every engine name the prose calls exists with the
keyword arguments it shows."""
from __future__ import annotations

import importlib
import inspect
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
from PIL import Image

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()
PYTHON_BLOCKS = re.findall(r"^```python\n(.*?)^```", README, flags=re.S | re.M)
# Where the prose's bare names live, searched in order.
NAMESPACES = ("components", "engine", "shell", "engine.assets.mesh", "engine.assets.texture_data",
              "engine.assets.portals", "engine.assets.models")
NOT_PYTHON = {"layout"}  # GLSL's layout(binding=), named under Requirements


def test_the_readme_has_its_python_examples():
    assert len(PYTHON_BLOCKS) >= 2  # the tiny game and the mirror/portal/probe game


def test_every_readme_python_block_runs_and_renders_a_picture(tmp_path):
    """Each block is a whole program (a Game and ``run``): saved as a file and run the way its
    own first line says, it exits 0 and writes a frame with something in it.  Each runs as a
    program of its own forked from one interpreter that has imported the engine
    (``tests/forked_scripts.py``: the imports were most of each run's time)."""
    for index, code in enumerate(PYTHON_BLOCKS):
        assert 'if __name__ == "__main__":' in code and "run(" in code, \
            f"README python block {index} is not a runnable program:\n{code[:200]}"
    jobs = []
    for index, code in enumerate(PYTHON_BLOCKS):
        script = tmp_path / f"readme_block_{index}.py"
        script.write_text(code)
        jobs.append({"script": str(script), "cwd": str(tmp_path), "stdout": str(tmp_path / f"out_{index}.txt"),
                     "stderr": str(tmp_path / f"err_{index}.txt"),
                     "args": ["--headless", "--frames", "1", "--size", "160x90",
                              "--out", str(tmp_path / f"out_{index}")]})
    (tmp_path / "jobs.json").write_text(json.dumps(jobs))
    # (a worker a core: all at once, each block's 120 s ran out while forty compiled their
    # shaders together on a machine with no shader cache)
    done = subprocess.run([sys.executable, "-m", "tests.forked_scripts", str(tmp_path / "jobs.json"),
                           "--workers", str(os.cpu_count() or 2), "--timeout", "120"],
                          cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)}, capture_output=True, text=True,
                          timeout=1200)
    assert done.returncode == 0, done.stderr[-3000:]
    statuses = json.loads(done.stdout.splitlines()[-1])
    assert len(statuses) == len(PYTHON_BLOCKS)
    for index, status in enumerate(statuses):
        assert status == 0, f"README python block {index} failed (exit {status}):\n" \
                            f"{(tmp_path / f'err_{index}.txt').read_text()[-2000:]}"
        frame = np.asarray(Image.open(tmp_path / f"out_{index}" / "frame_0000.png")).astype(float)
        assert frame.shape == (90, 160, 3)
        # (A blank frame's deviation is 0; the lowest a block's has, the mist's, about 10.)
        assert frame.mean() > 20 and frame.std() > 5, f"README python block {index} rendered a blank frame"


def resolve(name: str):
    """The object a README name such as ``look_rotation`` or ``engine.assets.spawn_model`` means."""
    if "." in name:
        module, _, attr = name.rpartition(".")
        return getattr(importlib.import_module(module), attr)
    for namespace in NAMESPACES:
        found = getattr(importlib.import_module(namespace), name, None)
        if found is not None:
            return found
    raise AssertionError(f"README names {name!r}, which none of {NAMESPACES} has")


def test_every_call_the_readme_prose_shows_exists_with_its_keywords():
    from components import Transform

    calls = re.findall(r"`([A-Za-z_][\w.]*)\(([^`]*)\)`", README)
    named = {name for name, _ in calls} | set(re.findall(r"`(checker_texture|load_texture)`", README))
    assert {"look_rotation", "yaw_pitch_rotation", "checker_texture",
            "engine.assets.texture_data.load_texture"} <= named
    for name, arguments in calls:
        if name in NOT_PYTHON:
            continue
        if name.startswith("t."):  # a Transform in the example: t.touch()
            assert callable(getattr(Transform, name[2:], None)), f"README calls Transform.{name[2:]}()"
            continue
        target = resolve(name)
        parameters = inspect.signature(target).parameters
        for keyword in re.findall(r"\b(\w+)=", arguments):
            assert keyword in parameters, f"README shows {name}({keyword}=...), which it does not take"
    for name in named - {name for name, _ in calls}:
        resolve(name)
