"""smoke: a plume of smoke rising in curl-noise turbulence and drifting in the wind (tianim.particles).

A disc emitter on the ground releases 1500 puffs/s; buoyancy (an upward "gravity" of 0.6 m/s^2),
linear drag toward a 0.5 m/s side wind and divergence-free curl noise (Bridson et al. 2007) carry
them up and sideways. Each puff is drawn as a soft Gaussian sprite that grows, lightens and fades
over its 3 s +- 30 % life (SIZE, COLOUR and DENSITY, :mod:`tianim.keyframe` tracks over normalised
age), and the sprites are blended, not stacked: :func:`composite` treats them as a thin emitting and
absorbing medium, so overlapping puffs thicken smoothly and the ground shows through thin smoke.
The ground is drawn once by :class:`tianim.render.Scene3D`; the sprites are splatted onto it with its
camera (Camera.project), at half resolution (smoke has no sharp detail) and upsampled.
"""

from __future__ import annotations

import numpy as np
from PIL import Image

import tianim.physics as tp
from tianim import particles as tpar
from tianim.keyframe import Track
from tianim.render import Scene3D

TITLE = "smoke rising in curl-noise turbulence (soft blended sprites; size, colour and density over life)"
FRAMES = 120
PREROLL = 2.0  # [s] simulated before the first frame: the plume is up

#: sprite radius [m] (3 standard deviations of its Gaussian) over normalised age: puffs spread as they rise
SIZE = Track([0.0, 0.3, 1.0], [[0.07], [0.12], [0.24]], interpolation="linear")
COLOUR = Track([0.0, 0.4, 1.0], [[0.30, 0.30, 0.32], [0.45, 0.46, 0.49], [0.62, 0.63, 0.66]], interpolation="linear")
#: optical depth at a sprite's centre over normalised age: fades in near the source, out at the end of life
DENSITY = Track([0.0, 0.1, 0.5, 1.0], [[0.03], [0.09], [0.04], [0.0]], interpolation="linear")


def make_system(seed: int = 0) -> tpar.ParticleSystem:
    """The plume's particle system (capacity 6000, one copy)."""
    source = tpar.DiscEmitter(center=(0.0, 0.02, 0.0), radius=0.08, rate=1500.0, direction=(0.0, 1.0, 0.0), cone=0.4,
                              speed=(0.35, 0.6), lifetime=3.0, lifetime_variance=0.3)
    return tpar.ParticleSystem(
        6000, emitters=[source], gravity=(0.0, 0.6, 0.0),
        forces=[tpar.Drag(linear=0.8, wind=(0.5, 0.0, 0.0)), tpar.CurlNoise(amplitude=0.7, scale=0.35, seed=seed)],
        colliders=[tp.Ground(height=0.0, normal=(0.0, 1.0, 0.0), restitution=0.0, friction=0.2)], seed=seed)


def composite(background, xy, radius, colour, density):
    """Blend soft sprites over ``background`` (H, W, 3) floats in [0, 1]; returns a new (H, W, 3) image.

    Sprite i at pixel centre ``xy[i]`` (x right, y down) has the Gaussian footprint
    ``w_i(p) = exp(-|p - xy_i|^2 / (2 s_i^2))`` with ``s_i = radius[i] / 3`` [px] (cut at ``radius``),
    optical depth ``density[i] * w_i`` and colour ``colour[i]`` (M, 3). The sprites form a thin medium:
    transmittance ``T = exp(-sum_i density_i w_i)`` (Beer-Lambert), the medium's colour is the
    density-weighted mean ``C = sum_i density_i w_i c_i / sum_i density_i w_i`` (order-independent, as in
    McGuire & Bavoil 2013, "Weighted blended order-independent transparency"), and the pixel is
    ``C (1 - T) + background T``. A single sprite is then exactly alpha blending with
    ``alpha = 1 - exp(-density w)``.
    """
    bg = np.asarray(background, dtype=np.float64)
    H, W, _ = bg.shape
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    radius = np.asarray(radius, dtype=np.float64).reshape(-1)
    colour = np.asarray(colour, dtype=np.float64).reshape(-1, 3)
    density = np.asarray(density, dtype=np.float64).reshape(-1)
    tau = np.zeros(H * W)
    tc = np.zeros((3, H * W))
    half = np.ceil(radius).astype(np.int64)
    for k in np.unique(half):  # sprites of one stamp size at a time
        idx = np.flatnonzero(half == k)
        o = np.arange(-k, k + 1)
        cx, cy = np.floor(xy[idx, 0]).astype(np.int64), np.floor(xy[idx, 1]).astype(np.int64)
        px = cx[:, None, None] + o[None, None, :]  # (n, 1, 2k+1) pixel columns
        py = cy[:, None, None] + o[None, :, None]  # (n, 2k+1, 1) pixel rows
        dx = px + 0.5 - xy[idx, 0, None, None]
        dy = py + 0.5 - xy[idx, 1, None, None]
        s2 = (radius[idx] / 3.0)[:, None, None] ** 2
        r2 = dx * dx + dy * dy
        w = np.where(r2 <= radius[idx, None, None] ** 2, np.exp(-r2 / (2 * s2)), 0.0) * density[idx, None, None]
        inside = (px >= 0) & (px < W) & (py >= 0) & (py < H) & (w > 0)
        flat = (py * W + px)[inside]
        wi = w[inside]
        tau += np.bincount(flat, weights=wi, minlength=H * W)
        owner = np.broadcast_to(np.arange(len(idx))[:, None, None], inside.shape)[inside]
        for c in range(3):
            tc[c] += np.bincount(flat, weights=wi * colour[idx[owner], c], minlength=H * W)
    T = np.exp(-tau)
    C = tc / np.maximum(tau, 1e-300)
    out = bg.reshape(-1, 3) * T[:, None] + (C.T * (1 - T)[:, None])
    return out.reshape(H, W, 3)


def frames(width: int, height: int, n_frames: int, fps: float, substeps: int = 4):
    """Yield (height, width, 3) uint8 frames; the system advances one frame per image."""
    system = make_system()
    scene = Scene3D(width, height, ambient=0.85, specular=0.0, shadows=False)
    box = np.array([[-0.7, 0.0, -0.1], [0.2, 2.2, 1.1]])  # the plume's reach (1-99 % of puff positions)
    scene.particles(box, 0.01)
    camera = scene.frame(azimuth=-10.0, elevation=10.0, margin=1.0)
    scene.clear().ground(0.0, size=4.0, cell=0.25)
    background = scene.render()  # the camera is fixed and the ground never changes: drawn once
    w2, h2 = max(width // 2, 1), max(height // 2, 1)  # the sprite layer's resolution
    bg_half = np.asarray(Image.fromarray(background).resize((w2, h2), Image.BILINEAR), dtype=np.float64) / 255.0
    focal = camera.focal(h2)
    h = 1.0 / (fps * substeps)
    for _ in range(int(round(PREROLL * fps))):
        system.step(h, substeps)
    for _ in range(n_frames):
        live = np.flatnonzero(system.alive[0] > 0)
        u = system.normalized_age()[0, live]
        p = camera.project(system.x[0, live], w2, h2)
        front = p[:, 2] > 1e-3
        u, p = u[front], p[front]
        radius = np.maximum(focal * SIZE(u)[:, 0] / p[:, 2], 0.75)  # [px] on the half-size layer
        smoke = composite(bg_half, p[:, :2], radius, np.clip(COLOUR(u), 0, 1), np.clip(DENSITY(u)[:, 0], 0, None))
        # upsample only the smoke's change to the background, so the ground keeps its full resolution
        delta = smoke - bg_half
        up = np.stack([np.asarray(Image.fromarray(delta[..., c].astype(np.float32)).resize((width, height),
                                                                                         Image.BILINEAR))
                       for c in range(3)], axis=2)
        yield np.clip(np.rint(background + 255.0 * up), 0, 255).astype(np.uint8)
        system.step(h, substeps)
