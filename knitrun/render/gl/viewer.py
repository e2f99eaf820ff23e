"""``knitrun view``: a scene drawn by the GL backend in a window (glfw), interactively.

Controls
--------
=====================  =====================================================================================
input                  effect
=====================  =====================================================================================
left drag              orbit the camera about its look-at point (yaw about the scene's up, pitch)
scroll                 zoom (pinhole: distance to the look-at point; orthographic: the view's height)
right drag             turn the first directional light (yaw and pitch, as the camera)
← / →, space           previous / next frame of the yarn curves; play or pause (the frames loop)
1 … 6                  ablation: full, plain DS, + ξ, + Ψ^Fiber, no tables, factored (``ablations.ABLATIONS``)
r                      back to the scene's camera and lights
s                      save a screenshot (``view_NNNN.png`` in the working folder)
Esc, q                 quit
=====================  =====================================================================================

The window's title shows the frame, the ablation and the last frame's time in ms (drawing and display). The image is
the GL backend's linear HDR frame, tone-mapped as ``knitrun render`` writes PNGs (``data_formats.images.tonemap``)
by the backend's composite pass straight into the window (``GLRenderer.render(into=…)``: no read-back, no upload)
and shown at the scene camera's resolution. The renderer of each ablation is made on first use and kept (packs read
and textures uploaded once per ablation).

Without a display (no ``DISPLAY`` or ``WAYLAND_DISPLAY``, or glfw cannot open one) the command stops with a one-line
error; ``xvfb-run`` gives a virtual one (README). ``screenshot``: draw one frame, save the window's pixels and return
(what the documented screenshot command and the test use).
"""

from __future__ import annotations

import dataclasses
import math
import os
import time

import numpy as np

from data_formats.errors import FormatError
from knitrun.render.ablations import ABLATIONS
from knitrun.render.camera import scene_camera

KEY_ABLATIONS = ("full", "plain_ds", "xi", "xi_shadowing", "no_tables", "factored")  # keys 1 … 6
ORBIT_RAD_PER_PX = 0.005
ZOOM_PER_STEP = 0.9
PLAY_FPS = 12.0


class DisplayUnavailable(FormatError):
    """No display to open a window on: the message says what to do instead."""


def _rotate(v, axis, angle):
    """``v`` rotated by ``angle`` about the unit ``axis`` (Rodrigues)."""
    axis = axis / np.linalg.norm(axis)
    return (v * math.cos(angle) + np.cross(axis, v) * math.sin(angle)
            + axis * (axis @ v) * (1.0 - math.cos(angle)))


def orbit(camera, d_yaw, d_pitch, zoom=1.0):
    """The camera turned about its look-at point by ``d_yaw`` (about its up) and ``d_pitch`` (about its right), and
    zoomed by ``zoom`` (distance or orthographic height times it); pitch stops 1° short of the up axis."""
    look_at = np.asarray(camera.look_at, float)
    offset = np.asarray(camera.position, float) - look_at
    up = np.asarray(camera.up, float) / np.linalg.norm(camera.up)
    offset = _rotate(offset, up, d_yaw)
    right = np.cross(-offset, up)
    if np.linalg.norm(right) > 1e-12:
        elevation = math.asin(np.clip(offset @ up / np.linalg.norm(offset), -1, 1))
        limit = math.radians(89.0)
        d_pitch = float(np.clip(elevation + d_pitch, -limit, limit) - elevation)
        offset = _rotate(offset, right, -d_pitch)
    if camera.ortho_height > 0:
        return dataclasses.replace(camera, position=look_at + offset, ortho_height=camera.ortho_height * zoom)
    return dataclasses.replace(camera, position=look_at + offset * zoom)


def turn_light(direction, up, d_yaw, d_pitch):
    """A light direction turned like ``orbit`` turns the camera offset (unit result)."""
    d = _rotate(np.asarray(direction, float), up, d_yaw)
    right = np.cross(d, up)
    if np.linalg.norm(right) > 1e-12:
        d = _rotate(d, right, d_pitch)
    return d / np.linalg.norm(d)


def view(scene, packs=None, samples_per_segment: int = 4, screenshot=None, exposure: float = 0.0):
    """Open the viewer on ``scene`` (``data_formats.scene.Scene``) until the window closes; with ``screenshot`` (a
    path) draw one frame, save the window's pixels there as a PNG and return. DisplayUnavailable (one line) without
    a display; FormatError and GLUnavailable as the GL backend raises them."""
    if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        raise DisplayUnavailable("knitrun view needs a display and none is set (DISPLAY, WAYLAND_DISPLAY): on a "
                                 "headless machine use knitrun render --backend gl, or run under xvfb-run")
    import glfw
    import moderngl

    from knitrun.render.gl.gl_renderer import GLRenderer

    if not glfw.init():
        raise DisplayUnavailable(f"glfw could not open the display {os.environ.get('DISPLAY', '')!r}: is an X server "
                                 f"running there?")
    try:
        camera0 = scene_camera(scene)
        glfw.window_hint(glfw.CONTEXT_VERSION_MAJOR, 4)
        glfw.window_hint(glfw.CONTEXT_VERSION_MINOR, 5)
        glfw.window_hint(glfw.OPENGL_PROFILE, glfw.OPENGL_CORE_PROFILE)
        glfw.window_hint(glfw.RESIZABLE, False)
        window = glfw.create_window(camera0.width, camera0.height, "knit view", None, None)
        if not window:
            raise DisplayUnavailable("glfw opened the display but no OpenGL 4.5 core window on it")
        glfw.make_context_current(window)
        glfw.swap_interval(0)
        ctx = moderngl.create_context(require=450)
        state = _Viewer(scene, packs, samples_per_segment, ctx, window, exposure, GLRenderer)
        state.run(glfw, screenshot)
    finally:
        glfw.terminate()


class _Viewer:
    """The viewer's state: camera, light, frame, ablation, the renderers made so far (one per ablation)."""

    def __init__(self, scene, packs, samples_per_segment, ctx, window, exposure, renderer_class):
        self.scene, self.packs, self.sps, self.ctx, self.window = scene, packs, samples_per_segment, ctx, window
        self.exposure, self.renderer_class = exposure, renderer_class
        self.renderers = {}
        self.ablation = "full"
        renderer = self.renderer()
        self.frame, self.playing = scene.render.frame, False
        self.camera = scene_camera(scene)
        self.light_dir0 = renderer.light_dir.copy()
        self.light_dir = renderer.light_dir.copy()
        self.up = np.asarray(self.camera.up, float) / np.linalg.norm(self.camera.up)
        self.dirty, self.last_ms, self.drag, self.want_shot = True, 0.0, None, False

    def renderer(self):
        if self.ablation not in self.renderers:
            self.renderers[self.ablation] = self.renderer_class(self.scene, self.packs, ABLATIONS[self.ablation],
                                                                self.sps, ctx=self.ctx)
        return self.renderers[self.ablation]

    def draw(self, glfw):
        start = time.perf_counter()
        renderer = self.renderer()
        renderer.light_dir = self.light_dir.copy()
        renderer.render(self.frame, camera=self.camera, into=self.ctx.screen, exposure=self.exposure)
        glfw.swap_buffers(self.window)
        self.last_ms = (time.perf_counter() - start) * 1e3
        glfw.set_window_title(self.window, f"knit view — frame {self.frame + 1}/{renderer.frame_count} — "
                                           f"{self.ablation} — {self.last_ms:.0f} ms")
        self.dirty = False

    def screenshot(self, path):
        """The window's pixels (display values already: tone-mapped 8-bit sRGB) as a PNG, written atomically."""
        from PIL import Image

        from data_formats.atomic import atomic_path

        pixels = np.frombuffer(self.ctx.screen.read(components=3), np.uint8)
        image = np.ascontiguousarray(pixels.reshape(self.camera.height, self.camera.width, 3)[::-1])
        with atomic_path(path) as tmp:
            Image.fromarray(image).save(tmp, format="PNG")

    def run(self, glfw, screenshot):
        glfw.set_key_callback(self.window, lambda w, key, sc, action, mods: self.on_key(glfw, key, action))
        glfw.set_mouse_button_callback(self.window, lambda w, button, action, mods: self.on_button(glfw, button,
                                                                                                  action))
        glfw.set_cursor_pos_callback(self.window, lambda w, x, y: self.on_move(x, y))
        glfw.set_scroll_callback(self.window, lambda w, dx, dy: self.on_scroll(dy))
        if screenshot is not None:
            self.draw(glfw)
            self.screenshot(screenshot)
            return
        last_step = time.perf_counter()
        shots = 0
        while not glfw.window_should_close(self.window):
            glfw.poll_events() if self.playing or self.dirty else glfw.wait_events_timeout(0.1)
            if self.playing and time.perf_counter() - last_step >= 1.0 / PLAY_FPS:
                self.frame = (self.frame + 1) % self.renderer().frame_count
                last_step, self.dirty = time.perf_counter(), True
            if self.dirty:
                self.draw(glfw)
            if self.want_shot:
                shots += 1
                self.screenshot(f"view_{shots:04d}.png")
                self.want_shot = False

    # --- input ---------------------------------------------------------------------------------------------------

    def on_key(self, glfw, key, action):
        if action not in (glfw.PRESS, glfw.REPEAT):
            return
        count = self.renderer().frame_count
        if key in (glfw.KEY_ESCAPE, glfw.KEY_Q):
            glfw.set_window_should_close(self.window, True)
        elif key == glfw.KEY_RIGHT:
            self.frame = (self.frame + 1) % count
        elif key == glfw.KEY_LEFT:
            self.frame = (self.frame - 1) % count
        elif key == glfw.KEY_SPACE:
            self.playing = not self.playing
        elif glfw.KEY_1 <= key < glfw.KEY_1 + len(KEY_ABLATIONS):
            self.ablation = KEY_ABLATIONS[key - glfw.KEY_1]
        elif key == glfw.KEY_R:
            self.camera, self.light_dir = scene_camera(self.scene), self.light_dir0.copy()
        elif key == glfw.KEY_S:
            self.want_shot = True
        self.dirty = True

    def on_button(self, glfw, button, action):
        if action == glfw.PRESS:
            self.drag = (button, *glfw.get_cursor_pos(self.window))
        elif action == glfw.RELEASE:
            self.drag = None

    def on_move(self, x, y):
        if self.drag is None:
            return
        button, x0, y0 = self.drag
        dx, dy = (x - x0) * ORBIT_RAD_PER_PX, (y - y0) * ORBIT_RAD_PER_PX
        self.drag = (button, x, y)
        if button == 0:
            self.camera = orbit(self.camera, -dx, dy)
        elif len(self.light_dir):
            self.light_dir[0] = turn_light(self.light_dir[0], self.up, -dx, -dy)
        self.dirty = True

    def on_scroll(self, dy):
        self.camera = orbit(self.camera, 0.0, 0.0, ZOOM_PER_STEP ** dy)
        self.dirty = True
