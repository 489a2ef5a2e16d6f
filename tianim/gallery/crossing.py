"""crossing: 32 pedestrians on a circle walk to their antipodes, keeping right, avoiding each other with ORCA.

Agents of radius 0.3 m start evenly on a circle of radius 7 m and head for the opposite point at a
preferred speed of 1.3 m/s (max 2 m/s, time horizon 2 s; tianim.crowds.ORCA with its default
``safety`` margin of 0.25 r, so the discs never touch). Walking straight at the centre, the whole
circle meets there at once and ORCA's symmetric solutions jam for many seconds; so each pedestrian
first heads for a waypoint KEEP_RIGHT to the right of the centre (as people keep right in a
crossing) and, 1 m before the halfway line, turns for its antipode. The crowd turns into a
roundabout and everyone arrives in about 12.5 s (a free walk takes 11 s).

The video plays at real time: each frame advances 1 / fps seconds (in ORCA steps of at most
1/24 s). Discs are coloured by starting angle, white triangles show headings, small rings the
goals; the caption (in a band of its own above the circle) gives the time, the closest approach so
far over 2r and how many have arrived.
"""

from __future__ import annotations

import math

import numpy as np

from tianim.crowds import ORCA, CrowdSolver, circle_scenario, pair_distances
from tianim.gallery._layout import fit, font_size, label
from tianim.render import Canvas2D

TITLE = "pedestrians on a circle cross to their antipodes, keeping right, with ORCA (real time)"
FRAMES = 336  # 14 s at 24 fps: everyone arrives at about 12.5 s
N, R, RADIUS = 32, 7.0, 0.3
PREF_SPEED, MAX_SPEED, TIME_HORIZON = 1.3, 2.0, 2.0
ARRIVAL = 0.05  # [m] arrival radius
KEEP_RIGHT = R * math.sin(math.radians(30.0))  # [m] waypoint offset to the right of the centre (3.5 m)
MAX_DT = 1.0 / 24.0  # [s] the longest ORCA step
MARGIN = 0.8  # [m] drawn around the circle of starts and goals


def hues(n):
    """n colours around the hue circle (HSV with s = 0.65, v = 0.9) as (n, 3) floats."""
    h = np.arange(n) / n * 6.0
    k = np.stack([(5 + h) % 6, (3 + h) % 6, (1 + h) % 6], axis=1)
    return (0.9 - 0.9 * 0.65 * np.clip(np.minimum(k, 4 - k), 0, 1)).astype(np.float32)


def steps_per_frame(fps: float) -> int:
    """ORCA steps per frame so that each is at most MAX_DT and the frame covers 1 / fps seconds."""
    return max(1, math.ceil((1.0 / fps) / MAX_DT - 1e-9))


def simulate(n_frames: int, fps: float):
    """Yield per frame ``(t [s], x (N, 2) [m], heading (N, 2), arrived (N,) bool, closest [m])``: the
    state shown on that frame (``closest`` the smallest centre distance at the ends of all steps so
    far, inf before the first); 1 / fps simulated seconds between frames."""
    agents, goals = circle_scenario(N, R)
    start, final = agents.x[0].copy(), goals[0].copy()
    along = (final - start) / (2 * R)  # unit vectors start -> antipode
    right = np.stack([along[:, 1], -along[:, 0]], axis=1)
    waypoint = KEEP_RIGHT * right  # beside the centre, on each walker's right
    model = ORCA(goals=waypoint[None], pref_speed=PREF_SPEED, radius=RADIUS, time_horizon=TIME_HORIZON,
                 max_speed=MAX_SPEED, arrival_radius=ARRIVAL)
    to_goal = waypoint - start
    agents.heading[0] = to_goal / np.linalg.norm(to_goal, axis=1, keepdims=True)  # facing their waypoints
    state, solver = model.state(agents), CrowdSolver()
    steps = steps_per_frame(fps)
    dt = 1.0 / (fps * steps)
    turned = np.zeros(N, dtype=bool)
    closest = np.inf
    for _ in range(n_frames):
        x = state.x[0]
        # turn for the antipode 1 m before the halfway line: a walker is then >= 1 m from its waypoint, so
        # ORCA never records an arrival at the waypoint
        turned |= np.einsum("ij,ij->i", x - start, along) >= R - 1.0
        state.goal[0][turned] = final[turned]
        arrived = turned & (np.linalg.norm(x - final, axis=1) <= ARRIVAL)
        yield float(state.t[0]), x.copy(), state.heading[0].copy(), arrived, closest
        for _ in range(steps):
            solver.step(model, state, dt)
            closest = min(closest, float(pair_distances(state.x, RADIUS)[0][0]))


def layout(width: int, height: int):
    """``(extent, font size, caption xy [px])``: the circle fills the frame below a caption band."""
    fs = fit("t = 88.8 s   closest / 2r = 8.88   arrived 88/88", font_size(height, 0.032), width - 20)
    band = 2 * fs + 4 if fs else 0  # [px] above the circle, for the caption only
    half = R + MARGIN
    scale = min(width / (2 * half), (height - band) / (2 * half))  # [px/m]
    top = half + band / scale
    extent = (-0.5 * width / scale, 0.5 * width / scale, top - height / scale, top)
    return extent, fs, (10, max(2, (band - fs) // 2))


def frames(width: int, height: int, n_frames: int, fps: float):
    """Yield (height, width, 3) uint8 frames, 1 / fps simulated seconds apart (real time)."""
    extent, fs, xy = layout(width, height)
    canvas = Canvas2D(width, height, extent=extent, background="white")
    colours = hues(N)
    _, goals = circle_scenario(N, R)
    small = min(width, height) < 200
    for t, x, h, arrived, closest in simulate(n_frames, fps):
        canvas.clear()
        if small:  # a few pixels per agent: plain coloured discs read best
            canvas.discs(x, RADIUS, color=colours, outline=None)
        else:
            canvas.discs(goals[0], RADIUS * 0.45, color="white", outline="grey", outline_width=1.0)
            canvas.discs(x, RADIUS, color=colours, outline="dark", outline_width=1.0)
            canvas.triangles(x, h, size=1.4 * RADIUS, color="white")
        near = f"{closest / (2 * RADIUS):.2f}" if np.isfinite(closest) else "-"
        label(canvas, xy, f"t = {t:4.1f} s   closest / 2r = {near}   arrived {int(arrived.sum())}/{N}", fs, units="px")
        yield canvas.image()
