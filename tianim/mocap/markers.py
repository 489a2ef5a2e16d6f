"""A marker capture: positions (frames, markers, 3) with NaN for drop-outs, labels, rate and units."""

from __future__ import annotations

import numpy as np

from tianim._checks import check_choice, check_finite_scalar, fmt, marker_array

#: Length units a capture may be in, and their size in metres.
UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001}


class Markers:
    """Marker trajectories of one capture.

    Attributes
    ----------
    positions : (F, M, 3) float64, in ``units``; a missing marker (drop-out) is NaN in all 3 coordinates.
    labels : tuple of M distinct, non-empty marker names.
    rate : capture rate in Hz (frame ``f`` is at time ``f / rate`` seconds).
    units : ``"m"``, ``"cm"`` or ``"mm"`` (C3D files are usually in mm).

    A frame with any coordinate NaN counts as missing: the other coordinates are set NaN too,
    so that :attr:`valid` and the positions always agree. Infinite values are refused.
    """

    __slots__ = ("positions", "labels", "rate", "units")

    def __init__(self, positions, labels=None, rate=120.0, units="mm"):
        P = marker_array("positions", positions, missing="NaN for a missing marker")
        P[np.isnan(P).any(axis=2)] = np.nan
        M = P.shape[1]
        if labels is None:
            labels = tuple(f"M{i:03d}" for i in range(M))
        elif isinstance(labels, str):
            raise TypeError(f"labels={labels!r} must be a sequence of {M} names, not one string")
        else:
            labels = tuple(labels)
            bad = [s for s in labels if not isinstance(s, str) or not s.strip()]
            if bad:
                raise ValueError(f"labels holds {fmt(bad[0])}; every label must be a non-empty string")
            if len(labels) != M:
                raise ValueError(f"labels has {len(labels)} names for {M} markers; give one per marker")
            if len(set(labels)) != M:
                dup = next(s for s in labels if labels.count(s) > 1)
                raise ValueError(f"labels names {dup!r} twice; marker labels must be distinct")
        self.positions = P
        self.labels = labels
        self.rate = check_finite_scalar("rate", rate, lo=0.0, lo_open=True)
        self.units = check_choice("units", units, tuple(UNITS))

    @property
    def n_frames(self) -> int:
        return self.positions.shape[0]

    @property
    def n_markers(self) -> int:
        return self.positions.shape[1]

    @property
    def valid(self) -> np.ndarray:
        """(F, M) bool: True where the marker was seen."""
        return ~np.isnan(self.positions[..., 0])

    @property
    def times(self) -> np.ndarray:
        """(F,) frame times in seconds."""
        return np.arange(self.n_frames) / self.rate

    def index(self, label: str) -> int:
        """The column of marker ``label``."""
        try:
            return self.labels.index(label)
        except ValueError:
            raise KeyError(f"label={label!r} is not a marker of this capture; labels are {fmt(list(self.labels))}") from None

    def __getitem__(self, label: str) -> np.ndarray:
        """(F, 3) trajectory of marker ``label`` (a view)."""
        return self.positions[:, self.index(label)]

    def with_positions(self, positions) -> "Markers":
        """A new capture with the same labels, rate and units and these (F', M, 3) positions."""
        return Markers(positions, self.labels, self.rate, self.units)

    def to_units(self, units: str) -> "Markers":
        """The capture converted to ``units`` ("m", "cm", "mm")."""
        units = check_choice("units", units, tuple(UNITS))
        return Markers(self.positions * (UNITS[self.units] / UNITS[units]), self.labels, self.rate, units)

    def __repr__(self) -> str:
        miss = 1.0 - self.valid.mean()
        return (f"Markers({self.n_frames} frames x {self.n_markers} markers at {self.rate:g} Hz in {self.units}, "
                f"{100 * miss:.1f}% missing)")


__all__ = ["UNITS", "Markers"]
