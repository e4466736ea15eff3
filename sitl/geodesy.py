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
