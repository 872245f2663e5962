"""Headless rendering of the world on the CPU: moderngl with an EGL context (Mesa's llvmpipe).

One :class:`Renderer` per image size draws a textured triangle mesh (and moving boxes) with the
exact pinhole projection of a :class:`~stereovo.camera.StereoCamera`: pixel ``(u, v)`` of the
camera is the centre of row ``v``, column ``u`` of the image, so a point projected by
:meth:`StereoCamera.project` lands where the renderer drew it. Besides the grey image it writes
each pixel's depth ``z`` (m; 0 where nothing was drawn) and the id of the object drawn there
(0 for the static world, ``j + 1`` for moving object j).

The EGL context is made once per process. It does not survive ``fork``: Mesa's rasteriser
threads are not copied into the child, so a child forked from a process that had made a context
would hang on its first GL call. Such a child gets :class:`RenderingUnavailable` instead, saying to
start workers with ``"forkserver"`` or ``"spawn"`` (Gymnasium: ``gymnasium.make_vec(...,
vectorization_mode="async", vector_kwargs={"context": "forkserver"})``); a child forked before
the parent made its context (or from one that only imported moderngl) makes its own. Needs the
``render`` extra (moderngl, glcontext) and the system's EGL with Mesa (Debian: ``libegl1
libegl-mesa0 libgl1-mesa-dri``; ``scripts/setup.sh`` installs them).
"""

from __future__ import annotations

import os

import numpy as np

from stereovo.camera import StereoCamera

_VERTEX = """
#version 330
uniform mat4 world_to_camera;
uniform vec4 intrinsics;   // 2 fx / W, 2 (cx + 0.5) / W - 1, 2 fy / H, 1 - 2 (cy + 0.5) / H
uniform vec2 clip_range;   // near, far (m)
in vec3 in_position;
in vec3 in_texture;
in float in_shade;
out vec3 v_texture;
out float v_shade;
out float v_depth;
void main() {
    vec4 p = world_to_camera * vec4(in_position, 1.0);
    float n = clip_range.x, f = clip_range.y;
    gl_Position = vec4(intrinsics.x * p.x + intrinsics.y * p.z, -intrinsics.z * p.y + intrinsics.w * p.z,
                       (f + n) / (f - n) * p.z - 2.0 * f * n / (f - n), p.z);
    v_texture = in_texture;
    v_shade = in_shade;
    v_depth = p.z;
}
"""

_FRAGMENT = """
#version 330
uniform sampler2DArray textures;
uniform float object_id;
in vec3 v_texture;
in float v_shade;
in float v_depth;
layout(location = 0) out float grey;
layout(location = 1) out vec2 depth_id;
void main() {
    grey = texture(textures, v_texture).r * v_shade;
    depth_id = vec2(v_depth, object_id);
}
"""

NEAR, FAR = 0.3, 400.0
"""Clip range of the renderer (m)."""

_CONTEXT: list[object] = []  # the process's context, once made

_MADE_HERE = False
"""This process has made (or tried to make) a GL context."""
_FORKED_AFTER_GL = False
"""This process was forked (``os.fork``, multiprocessing's ``"fork"``) from one that had made a GL
context, or from a descendant of one: its inherited Mesa state deadlocks on the first GL call."""


def _after_fork_in_child() -> None:
    global _MADE_HERE, _FORKED_AFTER_GL
    _FORKED_AFTER_GL = _FORKED_AFTER_GL or _MADE_HERE
    _MADE_HERE = False


if hasattr(os, "register_at_fork"):  # POSIX; Windows has no fork
    os.register_at_fork(after_in_child=_after_fork_in_child)

FORKED_MESSAGE = (
    "this process was forked from one that had made an OpenGL context, and Mesa's state does not survive "
    "fork (rendering here would hang): start worker processes with the 'forkserver' or 'spawn' method, e.g. "
    "gymnasium.make_vec(..., vectorization_mode='async', vector_kwargs={'context': 'forkserver'}), "
    "AsyncVectorEnv(env_fns, context='forkserver') or multiprocessing.get_context('forkserver')"
)
"""The message of :class:`RenderingUnavailable` in a forked child of a process that had rendered."""


class RenderingUnavailable(RuntimeError):
    """No headless OpenGL context can be used here: moderngl or EGL is missing (the message says what
    to install), or this process was forked from one that had made a context (the message says to
    use the ``forkserver`` or ``spawn`` start method)."""


def _check_not_forked() -> None:
    if _FORKED_AFTER_GL:
        raise RenderingUnavailable(FORKED_MESSAGE)


def context():
    """The process's moderngl EGL context (made on first use).

    Raises:
        RenderingUnavailable: moderngl or EGL is missing, or this process was forked from one that
            had made a context (see the module's docstring).
    """
    global _MADE_HERE
    _check_not_forked()
    if not _CONTEXT:
        try:
            import moderngl
        except ImportError as err:
            raise RenderingUnavailable(
                "rendered sequences need moderngl: pip install 'vo-gym[render]' (moderngl, glcontext)"
            ) from err
        _MADE_HERE = True  # before the attempt (a failed one may have started Mesa)
        try:
            ctx = moderngl.create_standalone_context(backend="egl", require=330)
        except Exception as err:  # glcontext raises plain Exceptions naming the missing library
            raise RenderingUnavailable(
                f"no headless OpenGL (EGL) context: {err}. On Debian/Ubuntu install libegl1 libegl-mesa0 "
                "libgl1-mesa-dri (scripts/setup.sh does)"
            ) from err
        _CONTEXT.append(ctx)
    return _CONTEXT[0]


def _matrix(m: np.ndarray) -> bytes:
    return np.ascontiguousarray(np.asarray(m, dtype=np.float32).T).tobytes()  # GL reads column-major


class Renderer:
    """Draws one world for one camera: grey images, depth and object ids.

    Args:
        camera: the rig; images are ``camera.height x camera.width``.
        vertices: ``(V, 7)`` float32 static mesh (:mod:`stereovo.sequences.world`).
        objects: meshes ``(Vj, 7)`` of the moving objects, in their own frames.
        textures: ``(L, S, S)`` uint8 texture layers.
    """

    def __init__(self, camera: StereoCamera, vertices: np.ndarray, objects: list[np.ndarray],
                 textures: np.ndarray) -> None:
        import moderngl

        ctx = context()
        self.camera = camera
        self._ctx = ctx
        w, h = int(camera.width), int(camera.height)
        self._program = ctx.program(vertex_shader=_VERTEX, fragment_shader=_FRAGMENT)
        self._program["intrinsics"].value = (
            2 * camera.fx / w, 2 * (camera.cx + 0.5) / w - 1, 2 * camera.fy / h, 1 - 2 * (camera.cy + 0.5) / h,
        )
        self._program["clip_range"].value = (NEAR, FAR)
        layers, size = textures.shape[0], textures.shape[1]
        self._texture = ctx.texture_array((size, size, layers), 1, np.ascontiguousarray(textures).tobytes())
        self._texture.build_mipmaps()
        # trilinear; llvmpipe's anisotropic filtering costs ten times the frame
        self._texture.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
        self._program["textures"].value = 0

        def vao(mesh: np.ndarray):
            buffer = ctx.buffer(np.ascontiguousarray(mesh, dtype=np.float32).tobytes())
            return ctx.vertex_array(self._program, [(buffer, "3f 3f 1f", "in_position", "in_texture", "in_shade")]), buffer

        self._world, self._buffers = vao(vertices), []
        self._objects = [vao(mesh) for mesh in objects]
        self._grey = ctx.renderbuffer((w, h), 1, dtype="f1")
        self._depth_id = ctx.renderbuffer((w, h), 2, dtype="f4")
        self._zbuffer = ctx.depth_renderbuffer((w, h))
        self._fbo = ctx.framebuffer(color_attachments=[self._grey, self._depth_id], depth_attachment=self._zbuffer)
        self._size = (w, h)

    def draw(self, camera_to_world: np.ndarray, object_poses: list[np.ndarray], with_depth: bool):
        """Render from a camera pose.

        Args:
            camera_to_world: ``(4, 4)`` pose of the camera.
            object_poses: ``(4, 4)`` object-to-world pose of each moving object.
            with_depth: also read back depth and ids.

        Returns:
            ``grey (H, W)`` uint8, and if ``with_depth`` ``depth (H, W)`` float32 (m, 0 = nothing)
            and ``ids (H, W)`` int16.

        Raises:
            RenderingUnavailable: in a process forked from one that had made the context (a renderer
                inherited from the parent would hang).
        """
        _check_not_forked()
        ctx = self._ctx
        self._fbo.use()
        ctx.enable(ctx.DEPTH_TEST)
        ctx.disable(ctx.CULL_FACE)
        self._fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        self._texture.use(0)
        world_to_camera = np.linalg.inv(camera_to_world)
        self._program["world_to_camera"].write(_matrix(world_to_camera))
        self._program["object_id"].value = 0.0
        self._world[0].render()
        for j, ((vao, _), pose) in enumerate(zip(self._objects, object_poses)):
            self._program["world_to_camera"].write(_matrix(world_to_camera @ pose))
            self._program["object_id"].value = float(j + 1)
            vao.render()
        w, h = self._size
        grey = np.frombuffer(self._fbo.read(components=1, attachment=0, dtype="f1"), np.uint8).reshape(h, w)[::-1]
        if not with_depth:
            return np.ascontiguousarray(grey)
        raw = np.frombuffer(self._fbo.read(components=2, attachment=1, dtype="f4"), np.float32).reshape(h, w, 2)[::-1]
        return np.ascontiguousarray(grey), np.ascontiguousarray(raw[:, :, 0]), raw[:, :, 1].astype(np.int16)

    def release(self) -> None:
        """Free the GL objects (the context stays for the next renderer). Nothing in a process forked
        from the renderer's: the objects are the parent's, and a GL call here would hang."""
        if _FORKED_AFTER_GL:
            return
        for obj in (self._fbo, self._grey, self._depth_id, self._zbuffer, self._texture, self._program):
            obj.release()
        for vao, buffer in [self._world, *self._objects]:
            vao.release()
            buffer.release()
