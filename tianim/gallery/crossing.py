"""crossing: 40 pedestrians on a circle walk to their antipodes, avoiding each other with ORCA.

Agents of radius 0.3 m start evenly on a circle of radius 7 m and head for the opposite point at
a preferred speed of 1.2 m/s (max 2 m/s, time horizon 2 s; tianim.crowds.ORCA, 4 steps of 0.1 s
per frame). Discs are coloured by starting angle, white triangles show headings, small rings the
goals; the caption gives the time, the closest approach over 2r and how many have arrived.
"""

from __future__ import annotations

import numpy as np

from tianim.crowds import ORCA, CrowdSolver, circle_scenario, pair_distances
from tianim.render import Canvas2D

TITLE = "pedestrians on a circle cross to their antipodes with ORCA"
FRAMES = 120
N, R, RADIUS = 40, 7.0, 0.3
STEPS_PER_FRAME, DT = 4, 0.1


def hues(n):
    """n colours around the hue circle (HSV with s = 0.65, v = 0.9) as (n, 3) floats."""
    h = np.arange(n) / n * 6.0
    k = np.stack([(5 + h) % 6, (3 + h) % 6, (1 + h) % 6], axis=1)
    return (0.9 - 0.9 * 0.65 * np.clip(np.minimum(k, 4 - k), 0, 1)).astype(np.float32)


def frames(width: int, height: int, n_frames: int, fps: float):
    """Yield (height, width, 3) uint8 frames, 0.4 s of simulated time per frame."""
    agents, goals = circle_scenario(N, R)
    model = ORCA(goals=goals, pref_speed=1.2, radius=RADIUS, time_horizon=2.0, max_speed=2.0, arrival_radius=0.05)
    to_goal = goals - agents.x
    agents.heading[...] = to_goal / np.linalg.norm(to_goal, axis=2, keepdims=True)  # facing their goals
    agents, solver = model.state(agents), CrowdSolver()
    colours = hues(N)
    canvas = Canvas2D(width, height, extent=(-R - 1, R + 1, -R - 1, R + 1), background="white")
    small = min(width, height) < 200
    closest = np.inf
    for _ in range(n_frames):
        x, h = agents.x[0], agents.heading[0]
        canvas.clear()
        if small:  # a few pixels per agent: plain coloured discs read best
            canvas.discs(x, RADIUS, color=colours, outline=None)
        else:
            canvas.discs(goals[0], RADIUS * 0.45, color="white", outline="grey", outline_width=1.0)
            canvas.discs(x, RADIUS, color=colours, outline="dark", outline_width=1.0)
            canvas.triangles(x, h, size=1.4 * RADIUS, color="white")
            arrived = int(agents.arrived().sum())
            near = f"{closest:.2f}" if np.isfinite(closest) else "-"
            text = f"t = {agents.t[0]:4.1f} s   closest / 2r = {near}   arrived {arrived}/{N}"
            canvas.text((10, 10), text, size=14, units="px")
        yield canvas.image()
        for _ in range(STEPS_PER_FRAME):
            solver.step(model, agents, DT)
            closest = min(closest, float(pair_distances(agents.x, RADIUS)[0][0]) / (2 * RADIUS))
