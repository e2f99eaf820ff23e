"""The yarn-level bounce on the GPU: ``yarn_bounce.vertex_bounce`` as an OpenGL 4.5 compute shader
(``shaders/bounce.comp``), for the GL backend's frame.

Why: the bounce's pair sums (every polyline point against every neighbouring segment within ``REACH_RADII`` radii, two
phase-table reads per pair and light) were the GL frame's largest CPU cost, ~300 ms a frame on ``bench_render.py``'s
patch of 60 540 points on 2 cores (BENCHMARKS.md, issue 15, "Stop 72"). The shader runs the same sums, one
invocation per receiving point, on whatever runs the context's shaders.

What stays on the CPU: the inputs (``pipeline.bounce_inputs``: the thinned polylines, their tangents, the lights'
visibility at the points, looked up in the maps the GPU drew and read back) and the segments' per-light terms, sorted
into the neighbour grid (``yarn_bounce.sender_segments``, NumPy); what comes back is B, f and I at the thinned
points (``vertex_bounce``'s three arrays), which ``pipeline.frame_bounce`` interpolates to every point.

Buffers (std430, one ``vec4`` per row unless said; ``bounce.comp`` names them): per receiving point its position and
rest arc length, unit tangent and curve, the direction toward the camera, R_Y + S_Y; per curve its radius and phase
table; per segment its start and length, unit axis and radius, midpoint and its rest arc length, mean tangent and
curve, and per (segment, light) E V_d and θ_i; the grid's first segment per cell (int); the phase tables
(float, (K, ``PHASE_THETA``, ``PHASE_THETA``, ``PHASE_PHI``, 3)). Single precision: against the Numba kernel's double
precision B agrees to 1.7·10⁻⁴ of its largest on ``bench_render.py``'s patch (the pack's phase) and to 1·10⁻³ with
a random phase table, whose steep cells magnify the angles of nearly aligned directions (``tests/test_gl_render.py``).
"""

from __future__ import annotations

import numpy as np

from knitrun.render.yarn_bounce import REACH_RADII, BounceLights, BounceYarns, sender_segments

LOCAL_SIZE = 64  # invocations per work group (bounce.comp's local_size_x)


def _rows(*columns) -> np.ndarray:
    """(N, 4) float32 rows of the columns (each (N,) or (N, k)), zero-padded to four."""
    parts = [np.asarray(c, np.float64).reshape(len(c), -1) for c in columns]
    out = np.zeros((len(parts[0]), 4), np.float32)
    out[:, :sum(p.shape[1] for p in parts)] = np.concatenate(parts, axis=1)
    return out


def gpu_vertex_bounce(program, yarns: BounceYarns, lights: BounceLights, reach_radii: float = REACH_RADII) -> tuple:
    """(B (P, 3), f (P,), I (P, 3)) as ``yarn_bounce.vertex_bounce`` gives them, computed by ``program``, the compiled
    ``shaders/bounce.comp`` (``gl_renderer._programs``), on its context."""
    n = len(yarns.points)
    out, covered, arriving = np.zeros((n, 3)), np.zeros(n), np.zeros((n, 3))
    if n < 2 or len(yarns.radius) == 0 or len(lights.direction) == 0:
        return out, covered, arriving
    senders = sender_segments(yarns, lights, float(reach_radii * yarns.radius.max()))
    if not len(senders.length):
        return out, covered, arriving
    n_lights = len(lights.direction)
    per_light = np.concatenate([senders.power, senders.theta_light[:, :, None]], axis=2).reshape(-1, 4)
    arrays = [
        _rows(yarns.points, yarns.rest), _rows(yarns.tangent, yarns.curve), _rows(yarns.toward_camera),
        _rows(yarns.scattered), _rows(yarns.radius, yarns.phase_of), _rows(senders.start, senders.length),
        _rows(senders.axis, senders.radius), _rows(senders.mid, senders.rest_mid),
        _rows(senders.tangent, senders.curve), per_light.astype(np.float32),
        senders.cell_start.astype(np.int32), np.ascontiguousarray(yarns.phase, np.float32),
    ]
    ctx = program.ctx
    buffers = [ctx.buffer(np.ascontiguousarray(a).tobytes()) for a in arrays]
    results = [ctx.buffer(reserve=16 * n) for _ in range(2)]
    try:
        for binding, buffer in enumerate(buffers + results):
            buffer.bind_to_storage_buffer(binding)
        directions = np.zeros((program["light_dir"].array_length, 3), np.float32)  # the array, padded
        directions[:n_lights] = lights.direction
        program["light_dir"].write(directions.tobytes())
        program["n_points"].value, program["n_lights"].value = n, n_lights
        program["dims"].value = tuple(int(d) for d in senders.dims)
        program["origin"].value = tuple(float(o) for o in senders.origin)
        program["cell"].value, program["reach_radii"].value = float(senders.cell), float(reach_radii)
        program.run(-(-n // LOCAL_SIZE))
        first = np.frombuffer(results[0].read(), np.float32).reshape(n, 4)
        second = np.frombuffer(results[1].read(), np.float32).reshape(n, 4)
    finally:
        for buffer in buffers + results:
            buffer.release()
    return first[:, :3].astype(np.float64), first[:, 3].astype(np.float64), second[:, :3].astype(np.float64)
