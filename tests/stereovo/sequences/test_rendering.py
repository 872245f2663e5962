"""stereovo.sequences.rendering in worker processes: a child forked from a process that had made
the GL context is refused with a message naming the fix (it used to hang in Mesa); a forkserver
child, and a child forked before the parent made its context, render the parent's image bit for bit.

Each case runs in a fresh interpreter (this one may have rendered already) that bounds every wait:
on a hang it reports ``hung`` rather than hanging the test."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("moderngl", reason="rendered sequences need moderngl: pip install 'vo-gym[render]'")

ROOT = Path(__file__).resolve().parents[3]

WORKERS = '''
import hashlib, json, multiprocessing, queue as queues
import numpy as np
from stereovo.camera import StereoCamera
from stereovo.sequences import rendering
from stereovo.sequences.rendering import Renderer, RenderingUnavailable

CAMERA = StereoCamera(fx=50.0, fy=50.0, cx=32.0, cy=24.0, baseline=0.5, width=64, height=48)
TRIANGLE = np.array([[-20, -20, 5, 0, 0, 0, 1], [20, -20, 5, 1, 0, 0, 1], [0, 20, 5, 0.5, 1, 0, 0.5]], np.float32)
TEXTURES = np.arange(64, dtype=np.uint8).reshape(1, 8, 8) * 3
INHERITED = []  # the parent's renderer, as a forked child sees it


def draw(renderer=None):
    try:
        renderer = renderer or Renderer(CAMERA, TRIANGLE, [], TEXTURES)
        return "drew " + hashlib.sha256(renderer.draw(np.eye(4), [], False).tobytes()).hexdigest()
    except RenderingUnavailable as err:
        return f"refused: {err}"


def child(queue, inherited, grandchild):
    out = [draw(INHERITED[0] if inherited else None)]
    if grandchild:
        out += spawn("fork", False, False)
    queue.put(out)


def spawn(method, inherited, grandchild):
    ctx = multiprocessing.get_context(method)
    queue = ctx.Queue()
    process = ctx.Process(target=child, args=(queue, inherited, grandchild))
    process.start()
    try:
        return queue.get(timeout=60)
    except queues.Empty:
        return ["hung"]
    finally:
        process.join(5)
        if process.is_alive():
            process.kill()


if __name__ == "__main__":
    results = {"module": rendering.__file__, "fork before rendering": spawn("fork", False, False)}
    try:
        INHERITED.append(Renderer(CAMERA, TRIANGLE, [], TEXTURES))
    except RenderingUnavailable as err:
        print(json.dumps({"skip": str(err)}))
        raise SystemExit(0)
    results["parent"] = draw(INHERITED[0])
    results["fork after rendering"] = spawn("fork", False, True)
    results["renderer inherited by a fork"] = spawn("fork", True, False)
    results["forkserver after rendering"] = spawn("forkserver", False, False)
    print(json.dumps(results))
'''

REFUSED = ("refused: this process was forked from one that had made an OpenGL context, and Mesa's state does "
           "not survive fork (rendering here would hang): start worker processes with the 'forkserver' or "
           "'spawn' method, e.g. gymnasium.make_vec(..., vectorization_mode='async', vector_kwargs={'context': "
           "'forkserver'}), AsyncVectorEnv(env_fns, context='forkserver') or multiprocessing.get_context('forkserver')")


@pytest.fixture(scope="module")
def workers(tmp_path_factory):
    script = tmp_path_factory.mktemp("rendering") / "workers.py"
    script.write_text(WORKERS)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])])}
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=400, env=env)
    assert out.returncode == 0, out.stderr
    results = json.loads(out.stdout)
    if "skip" in results:  # pragma: no cover - only on a platform without EGL
        pytest.skip(f"NO HEADLESS OPENGL ON THIS MACHINE, rendered tests skipped: {results['skip']}")
    assert Path(results["module"]).is_relative_to(ROOT)  # this checkout's code ran, not an installed copy
    return results


def test_a_child_forked_after_the_parent_rendered_is_refused_and_a_forkserver_child_renders(workers):
    assert workers["parent"].startswith("drew ")
    assert workers["fork after rendering"] == [REFUSED, REFUSED]  # the child, and a fork of the child
    # the message's remedy works, bit for bit; so does a fork from before the parent made its context
    assert workers["forkserver after rendering"] == [workers["parent"]]
    assert workers["fork before rendering"] == [workers["parent"]]


def test_a_renderer_inherited_by_a_forked_child_refuses_to_draw_rather_than_hang(workers):
    assert workers["renderer inherited by a fork"] == [REFUSED]
