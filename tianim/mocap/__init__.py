"""Motion capture (chapter 15.4): marker data, C3D files, gap filling, filtering, resampling.

Pure NumPy; importing it loads neither Taichi nor scipy. C3D files need the ``mocap`` extra.

* :class:`Markers` - positions (frames, markers, 3), NaN drop-outs, labels, rate, units
* :func:`read_c3d`, :func:`write_c3d` - C3D files through the ``c3d`` package (``pip install tianim[mocap]``)
* :func:`fill_gaps` - linear, cubic, quintic (Woltring), rigid-body (Kabsch) and PCA fills, with a report
* :func:`butterworth` (zero-lag, dual-pass corrected), :func:`residual_cutoff` (Winter), :func:`savgol`
* :func:`resample` - between 24, 25, 29.97, 30, 60, 120 Hz or any positive rates
"""

from tianim.mocap.c3d import read_c3d, write_c3d
from tianim.mocap.filters import butterworth, residual_cutoff, savgol
from tianim.mocap.gaps import Gap, UnfillableGap, fill_gaps, find_gaps
from tianim.mocap.markers import Markers
from tianim.mocap.resample import NTSC, resample

__all__ = ["NTSC", "Gap", "Markers", "UnfillableGap", "butterworth", "fill_gaps", "find_gaps", "read_c3d",
           "resample", "residual_cutoff", "savgol", "write_c3d"]
