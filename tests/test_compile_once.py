"""A second call of the same solver on the same shapes compiles nothing: every kernel factory is cached
(``@cached_variants``), so the hundredth scene compiles nothing new (docs/architecture.md, "Kernel
conventions"). A factory that lost its cache recompiles its kernels on every call: the results stay the
same bits, only far slower, so no equality test sees it; this one counts Taichi's compiles."""

import numpy as np
import pytest
import tianim.physics as tp
from tianim.particles import Drag, ParticleSystem, PointEmitter


def _cloth(n=16, **kw):
    return tp.cloth(n, n, size=(0.3, 0.3), total_mass=0.05, pins="none", origin=(-0.15, 0.05, -0.15),
                    colliders=[tp.Ground(friction=0.5)], **kw)


def _stepper(name):
    """(model, state, step): one configuration of each kernel path."""
    if name.startswith("method-"):
        method = name[len("method-"):]
        model = _cloth(8)
        solver = tp.make_solver(method)
        dt = 1e-3 if method in ("xpbd", "implicit_euler") else 1e-5
        return model, model.state(), lambda m, s: solver.step(m, s, dt, 3)
    if name.startswith("particles-lanes"):
        ps = ParticleSystem(2000, emitters=[PointEmitter(rate=2000, speed=(1, 2), cone=0.3)], forces=[Drag(0.2)],
                            colliders=[tp.Ground(restitution=0.4)])
        ps.solver.lanes = int(name[-1])
        return ps.model, ps.state, lambda m, s: ps.solver.step(m, s, 1 / 240, 2)
    options = {
        "xpbd-lanes4": dict(lanes=4),
        "xpbd-scalar": dict(lanes=0),
        "xpbd-parallel": dict(layout="parallel"),
        "xpbd-compensated": dict(compensated=True),
        "xpbd-self_collision": dict(self_collision=tp.SelfCollision(thickness=0.015)),
        "xpbd-passes": dict(self_collision=tp.SelfCollision(thickness=0.015), strain_limit=0.1),
    }[name]
    model = _cloth(16, bending=1e-4 if name == "xpbd-passes" else 0.0)
    solver = tp.XPBD(iterations=2, **options)
    return model, model.state(), lambda m, s: solver.step(m, s, 1e-3, 3)


NAMES = ([f"method-{m}" for m in tp.METHODS] + ["xpbd-lanes4", "xpbd-scalar", "xpbd-parallel", "xpbd-compensated",
                                                 "xpbd-self_collision", "xpbd-passes", "particles-lanes1",
                                                 "particles-lanes8"])


@pytest.mark.parametrize("name", NAMES)
def test_a_second_call_compiles_no_kernel(name, count_compiles):
    model, state, step = _stepper(name)
    step(model, state)  # compiles (or loads from the disk cache) what the path needs
    compiled = count_compiles()
    before = np.copy(state.x)
    step(model, state)
    assert not np.array_equal(before, state.x), "the second call did not step"  # it ran its kernels
    assert compiled == [], f"{name}: the second call compiled {compiled}"
