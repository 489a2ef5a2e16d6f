"""Foot contacts (stance) on a real walk and foot sliding after retargeting onto other leg proportions.

Data: tests/data/cmu_12_01_walk_301.bvh (CMU subject 12, trial 1, cgspeed conversion; frame 0 is the
file's T-pose, frames 1-300 walk; see tests/data/SOURCES.md). References: the gait cycle's stance share
(about 60 % per foot, 20-25 % double support, no flight phase in walking: Perry and Burnfield, *Gait
Analysis*, 2nd ed., 2010, ch. 2); sliding measured against the source's own stance points, scaled."""

import pathlib

import numpy as np
import pytest

from tianim.mocap import read_bvh
from tianim.mocap.retarget import detect_contacts, foot_points, retarget

DATA = pathlib.Path(__file__).parent / "data"
INCH_PER_UNIT = 1 / 0.45  # CMU ASF "length 0.45": one file unit is 1/0.45 inch


@pytest.fixture(scope="module")
def cmu_walk():
    clip = read_bvh(DATA / "cmu_12_01_walk_301.bvh", scale=0.0254 * INCH_PER_UNIT)
    return clip.skeleton, clip.motion[1:], clip.fps  # frame 0 is the T-pose


def _feet(sk):
    return np.stack([foot_points(sk, sk.index(f)) for f in ("LeftFoot", "RightFoot")])


def test_stance_share_on_a_real_walk_is_the_gaits(cmu_walk):
    sk, m, fps = cmu_walk
    P = sk.positions(m)
    c = detect_contacts(P[:, _feet(sk)], fps)
    share, double, neither = c.mean(axis=0), c.all(axis=1).mean(), (~c.any(axis=1)).mean()
    assert np.all((0.55 <= share) & (share <= 0.70)), share  # measured 0.63, 0.63 (slow walk, 0.9 m/s)
    assert 0.15 <= double <= 0.35 and neither <= 0.02, (double, neither)
    # the ankle alone with a 2 cm band (the old default) misses most of stance
    ankle = detect_contacts(P[:, [sk.index("LeftFoot"), sk.index("RightFoot")]], fps, height_tol=0.02)
    assert ankle.mean() < 0.45


def test_heel_off_stance_stands_on_the_toe():
    """Closed form: the ankle rises and rotates forward about a toe that stays put (heel-off)."""
    F, fps = 50, 100.0
    ang = np.linspace(0, np.pi / 4, F)  # the foot pitches 45 degrees about the toe
    toe = np.zeros((F, 3))
    ankle = np.stack([-0.15 * np.cos(ang), 0.08 + 0.15 * np.sin(ang), np.zeros(F)], axis=1)
    pts = np.stack([ankle, toe], axis=1)[:, None]  # (F, 1 foot, 2 points, 3)
    assert detect_contacts(pts, fps).all()
    assert not detect_contacts(pts[:, :, :1], fps, height_tol=0.02)[F // 2:].any()  # the ankle alone: no
    with pytest.raises(ValueError, match="positions has shape"):
        detect_contacts(np.zeros((5, 3)), fps)
    with pytest.raises(ValueError, match="fps="):
        detect_contacts(pts, 0.0)


def _slide(sk, tg, m, res, fps):
    """Largest excess horizontal slide [m] of a target foot point over a stance run of that point in the
    source (low and slow), beyond the source's own slide there, scaled: (left, right)."""
    Ps, Pt = sk.positions(m), tg.positions(res.motion)
    out = []
    for f in ("LeftFoot", "RightFoot"):
        pts = foot_points(sk, sk.index(f))
        own = detect_contacts(Ps[:, pts][:, :, None], fps)  # each point as its own "foot": (F, P)
        worst = 0.0
        for k, p in enumerate(pts):
            on = np.flatnonzero(own[:, k])
            for run in np.split(on, np.flatnonzero(np.diff(on) > 1) + 1):
                if run.size >= 3:
                    t = np.ptp(Pt[run, p][:, [0, 2]], axis=0).max()
                    s = res.scale * np.ptp(Ps[run, p][:, [0, 2]], axis=0).max()
                    worst = max(worst, t - s)
        out.append(worst)
    return np.array(out)


def test_retargeted_real_walk_does_not_slide_with_other_leg_proportions(cmu_walk):
    sk, m, fps = cmu_walk
    off = sk.offsets.copy()
    for side in ("Left", "Right"):
        off[sk.index(f"{side}Leg")] *= 1.3   # a 30 % longer thigh (LeftLeg's offset is the femur)
        off[sk.index(f"{side}Foot")] *= 0.85  # a 15 % shorter shin
    tg = sk.with_offsets(off)
    res = retarget(sk, m, tg, fps)
    assert np.all(res.contacts.mean(axis=0) > 0.55)
    slide = _slide(sk, tg, m, res, fps)
    assert np.all(slide < 0.006), slide  # measured 2.8 and 1.5 mm
    old = retarget(sk, m, tg, fps, height_tol=0.02)  # the old 2 cm band: most of stance unplanted
    assert _slide(sk, tg, m, old, fps).max() > 0.02  # measured 5.6 cm
