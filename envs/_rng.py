"""Counter-based random numbers for resets: Philox4x32-10, vectorised over copies in NumPy.

A batched environment resets thousands of copies at once; drawing their starts from one
``np.random.Generator`` per copy costs a Python loop (~12 us a copy). A counter-based generator
(Salmon, Moraes, Dror and Shaw 2011, "Parallel random numbers: as easy as 1, 2, 3", Random123)
is a pure function ``block = philox(counter, key)``: copy ``k`` draws with key = its seed and
counter = (block, episode), all copies in one array expression, and a single environment seeded
``seed + k`` computes the same function on the same words, so it draws the same numbers bit for bit.

Words: ``key = (seed mod 2**32, seed >> 32 mod 2**32)``; ``counter = (block, episode mod 2**32,
episode >> 32, stream)``. Each block gives four 32-bit words; two words make one float64 in
[0, 1) with 53 random bits: ``((w0 << 32 | w1) >> 11) * 2**-53`` (the construction of NumPy's
``random()``), exact in IEEE arithmetic, so the result does not depend on the batch size.
"""

from __future__ import annotations

import numpy as np

_M0, _M1 = np.uint64(0xD2511F53), np.uint64(0xCD9E8D57)   # Philox4x32 multipliers (Random123)
_W0, _W1 = np.uint64(0x9E3779B9), np.uint64(0xBB67AE85)   # Weyl key increments (golden ratio, sqrt(3) - 1)
_MASK32 = np.uint64(0xFFFFFFFF)
_ROUNDS = 10
_TWO_M53 = 2.0 ** -53


def philox4x32(counter: np.ndarray, key: np.ndarray) -> np.ndarray:
    """Philox4x32-10 blocks: ``counter`` (..., 4) and ``key`` (..., 2) of 32-bit words (any
    unsigned dtype holding values < 2**32) -> (..., 4) uint64 holding 32-bit words."""
    c = [np.asarray(counter[..., i], np.uint64) & _MASK32 for i in range(4)]
    k0 = np.asarray(key[..., 0], np.uint64) & _MASK32
    k1 = np.asarray(key[..., 1], np.uint64) & _MASK32
    s32 = np.uint64(32)
    for r in range(_ROUNDS):
        if r:
            k0 = (k0 + _W0) & _MASK32
            k1 = (k1 + _W1) & _MASK32
        p0 = _M0 * c[0]   # exact: both factors < 2**32
        p1 = _M1 * c[2]
        c = [(p1 >> s32) ^ c[1] ^ k0, p1 & _MASK32, (p0 >> s32) ^ c[3] ^ k1, p0 & _MASK32]
    return np.stack(c, axis=-1)


def seed_key(seed) -> int:
    """A seed (a non-negative int) as the 64-bit key of a copy (seeds from 2**64 on wrap)."""
    return int(seed) % (1 << 64)


def uniforms(keys: np.ndarray, episodes: np.ndarray, n: int, stream: int = 0) -> np.ndarray:
    """``(B, n)`` float64 uniforms in [0, 1) for copies with 64-bit ``keys`` (B,) and episode
    numbers ``episodes`` (B,); ``stream`` separates independent uses within an episode."""
    keys = np.asarray(keys, np.uint64).reshape(-1)
    episodes = np.asarray(episodes, np.uint64).reshape(-1)
    b, blocks = keys.size, -(-2 * n // 4)
    s32 = np.uint64(32)
    counter = np.empty((b, blocks, 4), np.uint64)
    counter[..., 0] = np.arange(blocks, dtype=np.uint64)
    counter[..., 1] = (episodes & _MASK32)[:, None]
    counter[..., 2] = (episodes >> s32)[:, None]
    counter[..., 3] = np.uint64(stream)
    key = np.empty((b, blocks, 2), np.uint64)
    key[..., 0] = (keys & _MASK32)[:, None]
    key[..., 1] = (keys >> s32)[:, None]
    words = philox4x32(counter, key).reshape(b, blocks * 2, 2)[:, :n]
    bits = ((words[..., 0] << s32) | words[..., 1]) >> np.uint64(11)
    return bits.astype(np.float64) * _TWO_M53
