"""Golden trajectories of the frozen ArmReach versions: ArmReach-v0 and v1 (single env and
make_vec, 2 and 3 links, fixed seeds and actions) equal, bit for bit, the rollouts main wrote
before the arm moved onto the one contract (tests/golden/armreach_v0_v1.npz, written by
tests/_arm_golden_rollouts.py from main at 53eb68f)."""

import pathlib

import numpy as np

from _arm_golden_rollouts import rollouts

GOLDEN = pathlib.Path(__file__).parent / "golden" / "armreach_v0_v1.npz"


def test_frozen_armreach_versions_match_their_golden_rollouts():
    now = rollouts()
    with np.load(GOLDEN) as gold:
        assert sorted(gold.files) == sorted(now)
        for key in gold.files:
            assert gold[key].dtype == now[key].dtype and np.array_equal(gold[key], now[key]), key
