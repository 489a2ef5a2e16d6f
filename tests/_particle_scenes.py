"""Small particle scenes shared by the particle contract tests and the batch-equals-separate test:
a fountain (emitter with bursts, drag, curl noise, a bouncing ground), fireworks (death sub-emitters, a
killing ground), a granular pile (DEM contact in a domain), a planar float64 system (vortex, a sticking
ground) and flashes (a moving mesh and a box emitting births that mostly die within their step, whose
on-death children are born and die within it too: the births' cascades, per copy)."""

import numpy as np

import tianim.physics as tp
from tianim.particles import (BoxEmitter, CurlNoise, Drag, Granular, MeshEmitter, ParticleModel, PointEmitter,
                              SphereEmitter, SubEmitter, Vortex)


def _plain():
    return ParticleModel(300, emitters=[PointEmitter(rate=400, cone=0.4, speed=(2, 3), lifetime=0.3,
                                                     lifetime_variance=0.5, bursts=((0.05, 20),))],
                         forces=[Drag(linear=0.2), CurlNoise(amplitude=0.5, scale=0.3)],
                         colliders=[tp.Ground(restitution=0.4, friction=0.3)])


def _sub():
    rockets = PointEmitter(rate=20, speed=(3, 4), cone=0.2, lifetime=0.1, lifetime_variance=0.2)
    sparks = SubEmitter(SphereEmitter(radius=0.02, cone=np.pi, speed=(1, 2), lifetime=0.15), parent=0, on="death",
                        count=5)
    return ParticleModel(400, emitters=[rockets], sub_emitters=[sparks], colliders=[(tp.Ground(), "kill")])


def _granular():
    g = Granular(radius=0.03, stiffness=2e4, restitution=0.3, friction=0.5, tangential_damping=5.0)
    return ParticleModel(120, emitters=[BoxEmitter(lower=(-0.1, 0.1, -0.1), upper=(0.1, 0.3, 0.1), rate=600,
                                                   lifetime=10)],
                         granular=g, colliders=[tp.Ground(restitution=0.2, friction=0.5)],
                         domain=((-1, -0.1, -1), (1, 1, 1)))


def _planar():
    return ParticleModel(200, emitters=[SphereEmitter(center=(0, 1), radius=0.2, rate=300, lifetime=0.4,
                                                      speed=(0, 1), cone=3.0, bursts=((0.04, 15),))],
                         forces=[Vortex(center=(0, 0.5), strength=0.5)], colliders=[(tp.Ground(), "stick")],
                         dim=2, dtype=np.float64)


def _flashes():
    v = np.array([[0, 0.5, 0], [1, 0.5, 0], [0, 0.5, 1], [1, 0.7, 1]], float)
    sheet = MeshEmitter(vertices=v, faces=[[0, 1, 2], [1, 3, 2]], vertex_velocities=np.full((4, 3), 0.3),
                        inherit_velocity=0.7, rate=300, speed=(0, 0.5), cone=0.2, lifetime=0.006, lifetime_variance=0.5)
    box = BoxEmitter(lower=(-0.1, 0.2, -0.1), upper=(0.1, 0.3, 0.1), rate=200, lifetime=0.2, bursts=((0.01, 7),))
    glints = SubEmitter(PointEmitter(speed=(0.5, 1), cone=3.0, lifetime=0.002), parent=0, on="death", count=2)
    return ParticleModel(300, emitters=[sheet, box], sub_emitters=[glints], forces=[Drag(linear=0.1)])

