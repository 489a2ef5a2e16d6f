"""mocap: a synthesised walk captured as noisy markers with drop-outs; raw beside cleaned, both solved.

The capture (60 Hz) is virtual: :func:`tianim.mocap.walk` moves a 21-joint humanoid, markers
ride on every segment (four per segment, :func:`tianim.mocap.marker_set`), and the "cameras" add 5 mm of noise and
lose markers for 0.15-0.6 s at a time. Left, the raw capture: markers as seen (missing ones absent)
and the skeleton solved from them (:func:`tianim.mocap.solve_markers`). Right, the cleaned capture:
the gaps filled (:func:`tianim.mocap.fill_gaps`, method ``auto``: splines for short gaps, the rigid
segment fill for long ones; filled markers drawn yellow), then a 6 Hz zero-lag Butterworth
(:func:`tianim.mocap.butterworth`), then solved. The camera follows the walkers.
"""

from __future__ import annotations

import numpy as np
from PIL import Image, ImageDraw

from tianim.gallery._layout import _font, fit, font_size
from tianim.mocap import butterworth, fill_gaps, marker_set, solve_markers, virtual_markers, walk
from tianim.render import Camera, Scene3D

TITLE = "motion capture: raw markers (noise, drop-outs) beside cleaned (gap fill + Butterworth), both solved"
FRAMES = 120
CAPTURE_HZ = 60.0
NOISE_M = 0.005
SEPARATION = 1.1  # metres between the raw (left) and cleaned (right) walkers


def capture(duration: float, seed: int = 12):
    """(skeleton, truth motion, marker joints, raw markers (F, M, 3) with NaN drop-outs) at CAPTURE_HZ."""
    n = max(int(np.ceil(duration * CAPTURE_HZ)) + 1, int(2.5 * CAPTURE_HZ))
    sk, motion = walk(n, CAPTURE_HZ)
    joints, local = marker_set(sk, per_segment=4)  # 4 per segment: one hidden leaves 3 donors for the rigid fill
    x = virtual_markers(sk, motion, joints, local)
    rng = np.random.default_rng(seed)
    raw = x + rng.normal(0.0, NOISE_M, x.shape)
    segs = np.unique(joints)
    # drop-outs: a marker hidden for 0.15-0.6 s, inside the clip, on a different segment each time (three
    # donors always stay for the rigid fill; PCA would take over, and cost more, for overlapping ones)
    for seg in rng.permutation(segs)[:min(segs.size, max(4, n // 12))]:
        m = int(rng.choice(np.flatnonzero(joints == seg)))
        length = int(rng.uniform(0.15, 0.6) * CAPTURE_HZ)
        start = int(rng.integers(1, max(2, n - length - 1)))
        raw[start:start + length, m] = np.nan
    return sk, motion, joints, local, raw


def clean(raw: np.ndarray, joints: np.ndarray) -> np.ndarray:
    """Gaps filled (``auto``, the markers grouped by segment for the rigid fill), then 6 Hz Butterworth."""
    segments = [np.flatnonzero(joints == j).tolist() for j in np.unique(joints)]
    filled, _ = fill_gaps(raw, CAPTURE_HZ, method="auto", segments=segments, on_unfillable="leave")
    still = np.isnan(filled)
    if still.any():  # anything no method could fill: the nearest seen value, so the filter has no holes
        for m in np.flatnonzero(still.any(axis=(0, 2))):
            ok = ~still[:, m, 0]
            for d in range(3):
                filled[:, m, d] = np.interp(np.arange(len(filled)), np.flatnonzero(ok), filled[ok, m, d])
    return butterworth(filled, CAPTURE_HZ, 6.0, axis=0)


def frames(width: int, height: int, n_frames: int, fps: float):
    """Both walkers at the video frames' times (the capture is sampled at the nearest capture frame)."""
    duration = n_frames / fps
    sk, motion, joints, local, raw = capture(duration)
    cleaned = clean(raw, joints)
    pick = np.minimum(np.round(np.arange(n_frames) / fps * CAPTURE_HZ).astype(int), len(raw) - 1)
    raw_v, clean_v = raw[pick], cleaned[pick]
    was_missing = np.isnan(raw_v).any(axis=-1)
    solved_raw = solve_markers(sk, raw_v, joints, local).motion
    solved_clean = solve_markers(sk, clean_v, joints, local).motion
    pos_raw, pos_clean = sk.fk(solved_raw)[0], sk.fk(solved_clean)[0]
    edges = sk.edges()
    left, right = np.array([-SEPARATION / 2, 0, 0]), np.array([SEPARATION / 2, 0, 0])

    scene = Scene3D(width, height)
    # framing: both walkers standing at the start, plus head room; then the camera follows the root
    box = np.concatenate([pos_raw[0] + left, pos_clean[0] + right, [[0, 0, -0.4], [0, 1.9, 0.4]]])
    scene.particles(box, 0.01)
    cam0 = scene.frame(azimuth=32.0, elevation=14.0, margin=1.0)
    z0 = float(pos_clean[0, 0, 2])
    big = max(width, height)
    r_marker = 0.018 if big >= 200 else 0.03
    r_bone = 0.016 if big >= 200 else 0.028
    fs = font_size(height, 0.035)
    captions = ("raw: 5 mm noise, drop-outs", "cleaned: gaps filled, 6 Hz Butterworth")
    fs = min([fit(c, fs, 0.46 * width) for c in captions] + [fs]) if fs else 0
    for k in range(n_frames):
        dz = np.array([0.0, 0.0, float(pos_clean[k, 0, 2]) - z0])
        scene.camera = Camera(eye=tuple(np.array(cam0.eye) + dz), target=tuple(np.array(cam0.target) + dz),
                              up=cam0.up, fov=cam0.fov)
        scene.clear()
        scene.ground(0.0, cell=0.25)
        scene.segments(pos_raw[k] + left, edges, radius=r_bone, color="#6b7280")
        scene.segments(pos_clean[k] + right, edges, radius=r_bone, color="#374151")
        seen = ~np.isnan(raw_v[k]).any(axis=-1)
        if seen.any():
            scene.particles(raw_v[k][seen] + left, r_marker, color="#d1495b")
        cols = np.where(was_missing[k][:, None], np.array([[0.93, 0.72, 0.13]]), np.array([[0.18, 0.62, 0.37]]))
        scene.particles(clean_v[k] + right, r_marker, color=cols)
        img = scene.render()
        if fs:
            image = Image.fromarray(img)
            pen = ImageDraw.Draw(image)
            font = _font(fs)
            for x0, text in ((int(0.02 * width), captions[0]), (int(0.52 * width), captions[1])):
                pen.text((x0, int(0.02 * height)), text, fill=(20, 20, 20), font=font)
            img = np.asarray(image)
        yield img
