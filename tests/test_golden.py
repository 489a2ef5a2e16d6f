"""Golden trajectories protect the frozen env versions (tests/golden/make_golden.py wrote them).

Each registered id's file holds a single env and a 3-copy vector env stepped with fixed actions from
seed 0. On a machine like the one that wrote the file (same Taichi package and version, same CPU
vector and FMA features: kernels are compiled for the host CPU) the rollout must repeat bit for bit;
elsewhere to float32 round-off (a changed dynamics, reward or reset moves them by far more).
"""

import numpy as np
import pytest

import envs
from golden.make_golden import file_for, machine_signature, rollout


@pytest.mark.parametrize("env_id", envs.ENV_IDS)
def test_frozen_env_versions_repeat_their_golden_rollout(env_id):
    path = file_for(env_id)
    assert path.exists(), f"{path} is missing: a new env id needs `python tests/golden/make_golden.py {env_id}`"
    with np.load(path) as f:
        want = {k: f[k] for k in f.files}
    got = rollout(env_id)
    same_machine = str(want.pop("signature")) == machine_signature()
    got.pop("signature")
    assert set(got) == set(want)
    for key, w in want.items():
        g = got[key]
        assert g.shape == w.shape, f"{env_id} {key}: shape {g.shape}, golden {w.shape}"
        if same_machine or g.dtype == bool:
            assert np.array_equal(g, w), f"{env_id} {key} differs from its golden rollout (max diff " \
                                         f"{np.max(np.abs(g.astype(float) - w.astype(float))):.3g})"
        else:
            np.testing.assert_allclose(g, w, rtol=1e-4, atol=1e-5, err_msg=f"{env_id} {key}")
