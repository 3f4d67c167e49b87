"""Run Python scripts as programs of their own, each forked from one interpreter that has
already imported the engine (``python -m tests.forked_scripts JOBS.json``).

Why: the README's ~40 examples are each a program a reader saves and runs, and each was a
fresh ``python script.py``; importing the engine, numpy and moderngl was most of each
run's time (0.9 of 1.0-1.5 s: 50 s of the suite's CPU for the examples).  A child forked
after those imports is a fresh program in every other way: its own process (its own GL
context, working folder, exit status, output), ``__main__`` the script, nothing any other
script did.

The jobs file: a list of ``{"script", "args", "cwd", "stdout", "stderr"}``.  At most
``--workers`` children run at once; a child running past ``--timeout`` seconds is killed.
The exit statuses are printed as one JSON list, the jobs' order (-9: killed).  Where there
is no ``os.fork`` (Windows) each script runs as ``python script`` instead.
"""
from __future__ import annotations

import argparse
import json
import os
import runpy
import signal
import subprocess
import sys
import time


def _child(job: dict) -> None:
    """In the forked child: become ``python script args`` and exit with its status."""
    status = 1
    try:
        for fd, path in ((1, job["stdout"]), (2, job["stderr"])):
            with open(path, "wb") as file:
                os.dup2(file.fileno(), fd)
        os.chdir(job["cwd"])
        sys.argv = [job["script"], *job["args"]]
        sys.path[0] = os.path.dirname(os.path.abspath(job["script"]))
        try:
            runpy.run_path(job["script"], run_name="__main__")
            status = 0
        except SystemExit as exit_:
            code = exit_.code
            status = code if isinstance(code, int) else (0 if code is None else 1)
            if not isinstance(code, int) and code is not None:
                print(code, file=sys.stderr)
        except BaseException:
            import traceback

            traceback.print_exc()
            status = 1
    finally:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(status)


def run_all(jobs: list[dict], workers: int, timeout: float) -> list[int]:
    """Each job's exit status, at most ``workers`` running at once."""
    if not hasattr(os, "fork"):
        return [_run_as_a_process(job, timeout) for job in jobs]
    statuses = [-9] * len(jobs)
    running: dict[int, tuple[int, float]] = {}  # pid -> (job index, when it started)
    waiting = list(range(len(jobs)))
    while waiting or running:
        while waiting and len(running) < workers:
            index = waiting.pop(0)
            pid = os.fork()
            if pid == 0:
                _child(jobs[index])
            running[pid] = (index, time.monotonic())
        pid, status = os.waitpid(-1, os.WNOHANG)
        if pid == 0:
            for child, (_, started) in running.items():
                if time.monotonic() - started > timeout:
                    os.kill(child, signal.SIGKILL)
            time.sleep(0.01)
            continue
        index, _ = running.pop(pid)
        statuses[index] = os.waitstatus_to_exitcode(status)
    return statuses


def _run_as_a_process(job: dict, timeout: float) -> int:
    with open(job["stdout"], "wb") as out, open(job["stderr"], "wb") as err:
        try:
            return subprocess.run([sys.executable, job["script"], *job["args"]], cwd=job["cwd"], stdout=out,
                                  stderr=err, timeout=timeout).returncode
        except subprocess.TimeoutExpired:
            return -9


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("jobs", help="a JSON file: a list of {script, args, cwd, stdout, stderr}")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 2)
    parser.add_argument("--timeout", type=float, default=120.0, help="seconds a script may run")
    args = parser.parse_args()
    with open(args.jobs) as file:
        jobs = json.load(file)
    # What the scripts import, imported once here (each child starts with it done).
    import moderngl  # noqa: F401
    import numpy  # noqa: F401

    import components  # noqa: F401
    import engine  # noqa: F401
    import shell  # noqa: F401
    import shell.app  # noqa: F401
    import shell.runner  # noqa: F401

    print(json.dumps(run_all(jobs, max(1, args.workers), args.timeout)))


if __name__ == "__main__":
    main()
