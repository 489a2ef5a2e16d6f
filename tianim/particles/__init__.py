"""Particle systems (Reeves 1983): a fixed-capacity pool for B copies, emitters (point, box, sphere,
disc, mesh surface), sub-emitters on death and collision, forces (drag toward wind, attractors,
vortices, curl noise), colliders (tianim.physics Ground and Sphere in bounce/stick/kill modes) and
DEM soft-sphere contact through
:class:`tianim.spatial.NeighbourGrid`. See :mod:`tianim.particles.system`.
"""

from tianim.particles.emitters import BoxEmitter, DiscEmitter, Emitter, PointEmitter, SphereEmitter
from tianim.particles.mesh_emitter import MeshEmitter
from tianim.particles.subemitters import SubEmitter
from tianim.particles.forces import Attractor, CurlNoise, Drag, Vortex, curl_noise
from tianim.particles.system import Granular, ParticleModel, ParticleSolver, ParticleState, ParticleSystem

__all__ = ["Attractor", "BoxEmitter", "CurlNoise", "DiscEmitter", "Drag", "Emitter", "Granular", "MeshEmitter", "ParticleModel", "ParticleSolver", "ParticleState",
           "ParticleSystem", "PointEmitter", "SphereEmitter", "SubEmitter", "Vortex", "curl_noise"]
