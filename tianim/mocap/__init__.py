"""Motion capture (chapter 15.4), pure NumPy: skeletons and BVH files, virtual markers, solving, retargeting.

* :class:`Skeleton` - BVH-style joints over the library's one joint tree; ``fk`` batched over frames
* :func:`humanoid`, :func:`walk` - a synthetic skeleton and procedural gait (no sample data ships)
* :func:`marker_set`, :func:`virtual_markers`, :func:`attach_markers` - markers rigidly attached to segments
"""

from tianim.mocap.skeleton import CHANNELS, Skeleton
from tianim.mocap.virtual import attach_markers, gait_angles, humanoid, marker_set, virtual_markers, walk

__all__ = ["CHANNELS", "Skeleton", "attach_markers", "gait_angles", "humanoid", "marker_set", "virtual_markers",
           "walk"]
