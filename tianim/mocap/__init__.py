"""Motion capture (chapter 15.4), pure NumPy: importing it loads neither Taichi nor scipy.

Marker side (C3D files need the ``mocap`` extra):

* :class:`Markers` - positions (frames, markers, 3), NaN drop-outs, labels, rate, units
* :func:`read_c3d`, :func:`write_c3d` - C3D files through the ``c3d`` package (``pip install tianim[mocap]``);
  :func:`read_c3d_analog` (force plates, EMG), :func:`read_c3d_events` (foot strikes ...)
* :func:`label_markers` - unlabelled points labelled by tracking from one labelled frame
* :func:`fill_gaps` - linear, cubic, quintic (Woltring), rigid-body (Kabsch) and PCA fills, with a report
* :func:`butterworth` (zero-lag, dual-pass corrected), :func:`residual_cutoff` (Winter), :func:`savgol`
* :func:`resample` - between 24, 25, 29.97, 30, 60, 120 Hz or any positive rates
* :func:`filter_motion`, :func:`resample_motion` - the same on a skeleton's motion, Euler angles unwrapped
  across +-180 degrees first (:func:`unwrap_rotations`, :func:`wrap_rotations`)

Skeleton side:

* :class:`Skeleton` - BVH-style joints over the library's one joint tree; ``fk`` batched over frames
* :func:`read_bvh`, :func:`parse_bvh`, :func:`write_bvh`, :func:`format_bvh` - BVH files (:class:`Clip`,
  :class:`BvhError` naming the line)
* :func:`humanoid`, :func:`walk`, :func:`random_skeleton`, :func:`random_motion` - synthetic skeletons and
  motion (no sample data ships)
* :func:`marker_set`, :func:`virtual_markers`, :func:`attach_markers` - markers rigidly attached to segments
* :func:`solve_markers` - joint angles from markers (batched Levenberg-Marquardt on the tree)
* :func:`retarget` - onto other bone lengths and rest poses (joint names mapped), foot contacts planted by leg IK
* :func:`joint_quaternions`, :func:`slerp`, :func:`resample_rotations` - rotations as quaternions, resampling
  by slerp (no wraps, no Euler branch switches)
"""

from tianim.mocap.bvh import BvhError, Clip, format_bvh, parse_bvh, read_bvh, write_bvh
from tianim.mocap.c3d import Analog, Event, read_c3d, read_c3d_analog, read_c3d_events, write_c3d
from tianim.mocap.curves import filter_motion, resample_motion, unwrap_rotations, wrap_rotations
from tianim.mocap.filters import butterworth, residual_cutoff, savgol
from tianim.mocap.gaps import Gap, UnfillableGap, fill_gaps, find_gaps
from tianim.mocap.labelling import label_markers
from tianim.mocap.markers import Markers
from tianim.mocap.resample import NTSC, resample
from tianim.mocap.retarget import RetargetResult, detect_contacts, retarget
from tianim.mocap.skeleton import CHANNELS, Skeleton
from tianim.mocap.rigid import kabsch
from tianim.mocap.rotations import (
    euler_from_matrix,
    joint_quaternions,
    quat_from_matrix,
    quat_to_matrix,
    resample_rotations,
    slerp,
)
from tianim.mocap.solve import SolveResult, solve_markers
from tianim.mocap.virtual import (
    attach_markers,
    gait_angles,
    humanoid,
    marker_set,
    random_motion,
    random_skeleton,
    virtual_markers,
    walk,
)

__all__ = [
    # marker side
    "NTSC", "Gap", "Markers", "UnfillableGap", "butterworth", "fill_gaps", "find_gaps", "label_markers", "read_c3d",
    "resample", "residual_cutoff", "savgol", "write_c3d", "Analog", "Event", "read_c3d_analog", "read_c3d_events", "filter_motion", "resample_motion", "unwrap_rotations",
    "wrap_rotations",
    # skeleton side
    "BvhError", "CHANNELS", "Clip", "RetargetResult", "Skeleton", "SolveResult", "attach_markers",
    "detect_contacts", "euler_from_matrix", "format_bvh", "gait_angles", "humanoid", "kabsch", "marker_set",
    "parse_bvh", "random_motion", "random_skeleton", "read_bvh", "retarget", "solve_markers", "virtual_markers",
    "walk", "write_bvh", "joint_quaternions", "quat_from_matrix", "quat_to_matrix", "resample_rotations", "slerp",
]
