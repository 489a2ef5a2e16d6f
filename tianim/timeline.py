"""The chapter's basic algorithm ``for t = t1 .. t_end: render(q(t))`` (section 15.1).

A :class:`Timeline` samples any ``q(t)`` at a frame rate and calls a renderer
per frame. ``q(t)`` can be

* any callable ``t -> q`` (a :class:`tianim.keyframe.Track`, a ``PathMotion``, a closed form),
* a :class:`Simulation` (a running physics state, advanced to each frame time),
* a :class:`Clip` (recorded states at their own rate, linearly interpolated).

Frame rates: film is 24 fps (:data:`FILM`, the default); video is 25 fps
(:data:`PAL`) or 30 fps (:data:`NTSC`, exactly 30000/1001 = 29.97 in broadcast).
(The source chapter swaps film and video; see docs/architecture.md, "Errors in the source chapter".)

Usage::

    from tianim.timeline import Timeline, Simulation
    tl = Timeline(duration=4.0)                    # 96 frames at 24 fps
    sim = Simulation(tp.plan_steps(model, 1 / 24), state)   # substeps per frame from the stiffest mode
    tl.export("cloth.mp4", sim, lambda x, t: draw(x), size=(640, 480))
"""

from __future__ import annotations

import math
from typing import Callable, Iterator

import numpy as np

FILM = 24.0
PAL = 25.0
NTSC = 30000 / 1001
VIDEO = 30.0


def _check_fps(fps) -> float:
    if isinstance(fps, bool) or not isinstance(fps, (int, float, np.integer, np.floating)) or not (
            math.isfinite(fps) and 0 < fps <= 1000):
        raise ValueError(f"fps={fps!r} must be in (0, 1000] frames per second (film 24, video 25 or 30)")
    return float(fps)


class Timeline:
    """Frame times ``t_k = start + k / fps`` for ``k = 0 .. frames - 1``.

    Parameters
    ----------
    frames : int, optional
        Number of frames (>= 1). Give this or ``duration``.
    duration : float, optional
        Length [s]; ``frames = round(duration * fps)`` (at least 1).
    fps : float
        Frames per second (24 film by default; 25 or 30 video).
    start : float
        Time of the first frame [s].
    """

    def __init__(self, frames: int | None = None, duration: float | None = None, fps: float = FILM,
                 start: float = 0.0):
        self.fps = _check_fps(fps)
        if (frames is None) == (duration is None):
            raise ValueError("give exactly one of frames=N or duration=SECONDS")
        if duration is not None:
            if not (isinstance(duration, (int, float, np.number)) and math.isfinite(duration) and duration > 0):
                raise ValueError(f"duration={duration!r} must be > 0 seconds")
            frames = max(1, int(round(duration * self.fps)))
        if isinstance(frames, bool) or not isinstance(frames, (int, np.integer)) or frames < 1:
            raise ValueError(f"frames={frames!r} must be an integer >= 1")
        if not math.isfinite(start):
            raise ValueError(f"start={start!r} must be a finite time in seconds")
        self.frames = int(frames)
        self.start = float(start)

    @property
    def dt(self) -> float:
        """Frame duration 1/fps [s]."""
        return 1.0 / self.fps

    @property
    def times(self) -> np.ndarray:
        """(frames,) frame times [s]."""
        return self.start + np.arange(self.frames) / self.fps

    def __len__(self) -> int:
        return self.frames

    def sample(self, source) -> Iterator[tuple[float, object]]:
        """Yield ``(t, q(t))`` for every frame time."""
        for t in self.times:
            yield float(t), source(float(t))

    def render(self, source, renderer: Callable) -> Iterator[np.ndarray]:
        """Yield ``renderer(q(t), t)`` for every frame: the chapter's ``for t: render(q(t))``."""
        for t, q in self.sample(source):
            yield renderer(q, t)

    def export(self, path, source, renderer: Callable, size=None, progress: bool = True):
        """Render every frame to ``path`` (.mp4, .gif or .png sequence); returns an ExportResult.

        The path, size and rate are checked before ``source`` is sampled even once.
        """
        from tianim.render.export import FrameWriter

        with FrameWriter(path, self.fps, size=size, total=self.frames, progress=progress) as w:
            for frame in self.render(source, renderer):
                w.append(frame)
        return w.result


class Simulation:
    """A running physics simulation as ``q(t)``: calling it with a time advances the state there.

    Parameters
    ----------
    plan : tianim.physics.StepPlan
        From :func:`tianim.physics.plan_steps`: the model, the solver and its substeps per frame.
        The frame rate is ``1 / plan.frame_dt``.
    state : tianim.physics.State
        Advanced in place; its time ``state.t`` must not pass the requested times.
    copy : int or None
        Which batch copy to return (default 0); None returns all copies (B, N, D).

    Calling ``sim(t)`` steps from the state's time to ``t`` (a whole number of steps of
    ``plan.dt``) and returns a copy of the positions (N, D).
    """

    def __init__(self, plan, state, copy: int | None = 0):
        from tianim.physics.planner import StepPlan

        if not isinstance(plan, StepPlan):
            raise TypeError(f"plan={plan!r} must be a tianim.physics.StepPlan; make one with "
                            "tianim.physics.plan_steps(model, frame_dt=1 / fps)")
        if getattr(state, "model", None) is not plan.model:
            raise ValueError("state does not belong to the plan's model; create it with plan.model.state(...)")
        if copy is not None and not (isinstance(copy, (int, np.integer)) and 0 <= copy < state.batch):
            raise ValueError(f"copy={copy!r} must be None or a copy index in [0, {state.batch - 1}]")
        self.plan, self.state, self.copy = plan, state, copy
        self.fps = _check_fps(1.0 / plan.frame_dt)
        self.dt = plan.dt

    def __call__(self, t: float) -> np.ndarray:
        now = float(self.state.t[0])
        n = int(round((t - now) / self.dt))
        if n < 0:
            raise ValueError(f"t={t!r} is before the simulation's time {now!r}; a simulation only runs forward")
        if n:
            self.plan.solver.step(self.plan.model, self.state, self.dt, n)
        x = self.state.x
        return np.array(x if self.copy is None else x[self.copy])


class Clip:
    """Recorded states ``values[k]`` at times ``start + k / fps``, linearly interpolated (held at the ends).

    values : (T, ...) array; fps : recording rate [frames/s].
    """

    def __init__(self, values, fps: float = FILM, start: float = 0.0):
        v = np.asarray(values, dtype=np.float64)
        if v.ndim < 1 or v.shape[0] < 1:
            raise ValueError(f"values has shape {v.shape}; give at least one recorded state (T, ...)")
        self.values = v
        self.fps = _check_fps(fps)
        self.start = float(start)

    @property
    def duration(self) -> float:
        return (len(self.values) - 1) / self.fps

    def __call__(self, t: float) -> np.ndarray:
        u = (float(t) - self.start) * self.fps
        u = min(max(u, 0.0), len(self.values) - 1.0)
        k = min(int(math.floor(u)), len(self.values) - 2) if len(self.values) > 1 else 0
        if len(self.values) == 1:
            return self.values[0].copy()
        w = u - k
        return (1.0 - w) * self.values[k] + w * self.values[k + 1]
