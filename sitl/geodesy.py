"""Local east/north/up about the simulator's geodetic origin <-> WGS-84 latitude/longitude."""

import numpy as np
import pymap3d
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


class Geodesy:
    """WGS-84 conversions about one origin (pymap3d; no flat-earth shortcut).

    ``to_geodetic_many`` converts many points in one vectorised call: a scalar pymap3d call
    costs about 0.4 ms, one call for 50 points about the same.
    """

    __slots__ = ("alt_m", "lat_deg", "lon_deg")

    def __init__(self, lat_deg: float, lon_deg: float, alt_m: float) -> None:
        self.lat_deg = lat_deg
        self.lon_deg = lon_deg
        self.alt_m = alt_m

    def to_geodetic(self, east_m: float, north_m: float, up_m: float) -> tuple[float, float, float]:
        """(lat_deg, lon_deg, alt_m above the ellipsoid) of a local point."""
        lat, lon, alt = pymap3d.enu2geodetic(
            east_m, north_m, up_m, self.lat_deg, self.lon_deg, self.alt_m
        )
        return float(lat), float(lon), float(alt)

    def to_geodetic_many(
        self, east_m: FloatArray, north_m: FloatArray, up_m: FloatArray
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        lat, lon, alt = pymap3d.enu2geodetic(
            east_m, north_m, up_m, self.lat_deg, self.lon_deg, self.alt_m
        )
        return (
            np.asarray(lat, dtype=np.float64),
            np.asarray(lon, dtype=np.float64),
            np.asarray(alt, dtype=np.float64),
        )

    def to_local(self, lat_deg: float, lon_deg: float, alt_m: float) -> tuple[float, float, float]:
        """(east_m, north_m, up_m) of a geodetic point."""
        east, north, up = pymap3d.geodetic2enu(
            lat_deg, lon_deg, alt_m, self.lat_deg, self.lon_deg, self.alt_m
        )
        return float(east), float(north), float(up)


class AnchoredGeodesy:
    """Many slowly moving points to geodetic, with few pymap3d calls.

    Each of ``slot_count`` slots (a vehicle, a camera) keeps an anchor: its exact pymap3d
    conversion at a recent point and the Jacobian there (central differences of pymap3d over
    +-1 m). Nearby points are converted by that first-order expansion; a point more than
    ``reanchor_m`` from its anchor along any axis gets a new one (all such slots in one
    pymap3d call). The neglected second-order term is about d^2 / (2 R): under 1 mm within
    50 m, far below GLOBAL_POSITION_INT's 1e-7 degree (about 1 cm) resolution.
    """

    __slots__ = ("_anchor_enu", "_anchor_lla", "_geodesy", "_jacobian", "_reanchor_m")

    _OFFSETS = np.array(
        [[0, 0, 0], [1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]],
        dtype=np.float64,
    )

    def __init__(self, geodesy: Geodesy, slot_count: int, reanchor_m: float = 50.0) -> None:
        self._geodesy = geodesy
        self._reanchor_m = reanchor_m
        self._anchor_enu = np.full((slot_count, 3), np.nan)  # NaN: no anchor yet
        self._anchor_lla = np.zeros((slot_count, 3))
        self._jacobian = np.zeros((slot_count, 3, 3))

    def to_geodetic(self, slots: NDArray[np.intp], enu: FloatArray) -> FloatArray:
        """(lat_deg, lon_deg, alt_m) rows for points ``enu`` (rows: east, north, up) of
        ``slots`` (each slot at most once)."""
        offset = enu - self._anchor_enu[slots]
        near = np.max(np.abs(offset), axis=1) <= self._reanchor_m  # False for NaN
        if not np.all(near):
            self._reanchor(slots[~near], enu[~near])
            offset = enu - self._anchor_enu[slots]
        lla: FloatArray = self._anchor_lla[slots] + np.einsum(
            "kij,kj->ki", self._jacobian[slots], offset
        )
        return lla

    def _reanchor(self, slots: NDArray[np.intp], enu: FloatArray) -> None:
        points = (enu[:, None, :] + self._OFFSETS[None, :, :]).reshape(-1, 3)
        lat, lon, alt = self._geodesy.to_geodetic_many(points[:, 0], points[:, 1], points[:, 2])
        lla = np.stack([lat, lon, alt], axis=1).reshape(len(slots), len(self._OFFSETS), 3)
        self._anchor_enu[slots] = enu
        self._anchor_lla[slots] = lla[:, 0]
        # columns: d(lat, lon, alt) / d(east, north, up), central differences over 2 m
        self._jacobian[slots] = np.stack(
            [
                (lla[:, 1] - lla[:, 2]) / 2.0,
                (lla[:, 3] - lla[:, 4]) / 2.0,
                (lla[:, 5] - lla[:, 6]) / 2.0,
            ],
            axis=2,
        )
