"""Grain size distributions defined by a sieve curve, and sampling disk diameters from them.

A sieve curve gives, at apertures d_0 < d_1 < ... < d_K, the percent of the material *by mass*
that passes, P_0 = 0 <= P_1 <= ... <= P_K = 100. For grains of one material, percent by mass is
percent by volume (3D) and, for the disks of a 2D model of unit thickness, percent by *area*.

Interpolation: P is linear in ln d between the points (the usual semi-log sieve plot drawn with
straight segments). On a segment k the mass density per unit ln d is then constant,

    dM/d(ln d) = s_k = (P_{k+1} - P_k) / (100 ln(d_{k+1} / d_k)),

and since a disk's mass is proportional to d^2 the *number* density of grains is

    dN/d(ln d) ∝ s_k d^{-2},    i.e.  within a segment, t = d^{-2} is uniformly distributed by number,

with the number weight of segment k proportional to N_k = s_k (d_k^{-2} - d_{k+1}^{-2}) / 2.
Sampling inverts this number distribution exactly (no binning) and stratifies the uniforms
(u_i = (i + U_i)/n), so even 70 grains follow the curve closely and 1e5 grains reproduce it to
far better than one percentage point (tests/generation/test_gsd.py).

Diameters are in metres throughout; the shipped curves (gransim/generation/data/*.csv) are written
in mm and converted on loading.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np

from .._validate import as_array, as_int, as_positive_float
from ..errors import InputError

#: directory (package resource) holding the named sieve curves, one ``<name>.csv`` each
_DATA = "data"


@dataclass(frozen=True, eq=False)
class GrainSizeDistribution:
    """A sieve curve: percent passing by mass (= by area for 2D disks) against aperture.

    Attributes
    ----------
    diameters : (K,) float64
        Sieve apertures d_k (m), strictly increasing, > 0, K >= 2.
    passing : (K,) float64
        Percent passing by mass P_k, non-decreasing, P_0 = 0 and P_{K-1} = 100.
    name : str
        Label (the shipped curves use their registry name).
    source : str
        Where the curve comes from (free text; the shipped curves quote their CSV header).

    Notes
    -----
    Between points the curve is linear in ln d (see the module docstring). The grain diameters
    therefore lie in [d_0, d_{K-1}]. Arrays are read-only copies; :meth:`scaled` returns a new object.
    """

    diameters: np.ndarray
    passing: np.ndarray
    name: str = "custom"
    source: str = ""

    def __post_init__(self):
        d = as_array(self.diameters, "diameters", (None,))
        p = as_array(self.passing, "passing", (d.shape[0],))
        if d.shape[0] < 2:
            raise InputError(f"diameters: a sieve curve needs at least 2 points, got {d.shape[0]}")
        if np.any(d <= 0):
            raise InputError(f"diameters: must be > 0, got {float(d[d <= 0][0])!r}")
        if np.any(np.diff(d) <= 0):
            k = int(np.argmax(np.diff(d) <= 0))
            raise InputError(
                f"diameters: must be strictly increasing (d[{k}] = {float(d[k])!r} >= d[{k + 1}] = {float(d[k + 1])!r})"
            )
        if np.any(np.diff(p) < 0):
            k = int(np.argmax(np.diff(p) < 0))
            raise InputError(
                f"passing: must be non-decreasing (P[{k}] = {float(p[k])!r} > P[{k + 1}] = {float(p[k + 1])!r})"
            )
        if p[0] != 0.0 or p[-1] != 100.0:
            raise InputError(
                f"passing: must start at 0 and end at 100 percent, got {float(p[0])!r} ... {float(p[-1])!r}"
            )
        for name, arr in (("diameters", d), ("passing", p)):
            arr = arr.copy()
            arr.flags.writeable = False
            object.__setattr__(self, name, arr)

    # -- construction -----------------------------------------------------------------------
    @classmethod
    def from_csv(cls, path, name: str | None = None, unit: float = 1e-3) -> GrainSizeDistribution:
        """Read a sieve curve from a CSV file (``#`` comment lines, a header row, two columns).

        Parameters
        ----------
        path : path-like
            Columns: diameter, percent passing. Comment lines starting with ``#`` become ``source``.
        name : str, optional
            Label; defaults to the file stem.
        unit : float
            Metres per diameter unit of the file (default 1e-3: the file is in mm).
        """
        path = Path(path)
        try:
            text = path.read_text()
        except OSError as exc:
            raise InputError(f"{path}: cannot read sieve curve ({exc.strerror or exc})") from None
        return cls._parse(text, name or path.stem, unit, str(path))

    @classmethod
    def _parse(cls, text: str, name: str, unit: float, where: str) -> GrainSizeDistribution:
        comments, rows = [], []
        for line in text.splitlines():
            s = line.strip()
            if not s:
                continue
            if s.startswith("#"):
                comments.append(s.lstrip("#").strip())
                continue
            fields = [f.strip() for f in s.split(",")]
            try:
                rows.append([float(f) for f in fields])
            except ValueError:
                if rows:  # a non-numeric row after data
                    raise InputError(f"{where}: cannot parse line {line!r}") from None
                continue  # the header row
        if not rows or any(len(r) != 2 for r in rows):
            raise InputError(f"{where}: expected rows 'diameter,percent_passing'")
        arr = np.array(rows)
        try:
            return cls(arr[:, 0] * unit, arr[:, 1], name=name, source=" ".join(comments))
        except InputError as exc:  # name the file whose curve is wrong
            raise InputError(f"{where}: {exc}") from None

    # -- the curve --------------------------------------------------------------------------
    def percent_passing(self, d) -> np.ndarray:
        """Percent passing by mass at diameters ``d`` (m), linear in ln d; 0 below d_0, 100 above."""
        d = np.asarray(d, dtype=float)
        with np.errstate(divide="ignore"):
            return np.interp(np.log(d), np.log(self.diameters), self.passing, left=0.0, right=100.0)

    def diameter(self, percent) -> np.ndarray:
        """D_p: the aperture (m) through which ``percent`` of the mass passes (inverse of the curve).

        Where the curve is flat (a gap in the grading) the smallest such aperture is returned.
        """
        q = np.asarray(percent, dtype=float)
        if np.any((q < 0) | (q > 100)) or not np.all(np.isfinite(q)):
            raise InputError(f"percent: must lie in [0, 100], got {percent!r}")
        P, lnd = self.passing, np.log(self.diameters)
        k = np.clip(np.searchsorted(P, q, side="left"), 1, P.size - 1)  # P[k-1] < q <= P[k]
        lo, hi = P[k - 1], P[k]
        w = np.where(hi > lo, (q - lo) / np.where(hi > lo, hi - lo, 1.0), 0.0)
        out = np.exp(lnd[k - 1] + w * (lnd[k] - lnd[k - 1]))
        return np.where(q <= 0, self.diameters[0], out)

    @property
    def d10(self) -> float:
        """D10 (m): 10 % of the mass passes."""
        return float(self.diameter(10.0))

    @property
    def d50(self) -> float:
        """D50 (m): the weight-median diameter."""
        return float(self.diameter(50.0))

    @property
    def d60(self) -> float:
        """D60 (m)."""
        return float(self.diameter(60.0))

    @property
    def d90(self) -> float:
        """D90 (m)."""
        return float(self.diameter(90.0))

    @property
    def cu(self) -> float:
        """Coefficient of uniformity Cu = D60 / D10."""
        return self.d60 / self.d10

    @property
    def d_min(self) -> float:
        """Smallest grain diameter d_0 (m)."""
        return float(self.diameters[0])

    @property
    def d_max(self) -> float:
        """Largest grain diameter d_{K-1} (m)."""
        return float(self.diameters[-1])

    # -- the number distribution of disks --------------------------------------------------
    def _segments(self):
        """Per segment: t_hi = d_k^-2, t_lo = d_{k+1}^-2 and the normalised number weight."""
        d, P = self.diameters, self.passing
        s = np.diff(P) / 100.0 / np.diff(np.log(d))  # mass per unit ln d
        t_hi, t_lo = d[:-1] ** -2.0, d[1:] ** -2.0
        w = s * (t_hi - t_lo) / 2.0
        return t_hi, t_lo, w / w.sum()

    def number_fraction_below(self, d) -> np.ndarray:
        """Fraction of disks *by number* with diameter <= ``d`` (m)."""
        scalar = np.ndim(d) == 0
        d = np.atleast_1d(np.asarray(d, dtype=float))
        t_hi, t_lo, w = self._segments()
        t = d[:, None] ** -2.0
        # part of segment k below d: t between max(t, t_lo) and t_hi, uniform in t
        frac = np.clip((t_hi - np.maximum(t, t_lo)) / (t_hi - t_lo), 0.0, 1.0)
        out = frac @ w
        return float(out[0]) if scalar else out.reshape(np.shape(d))

    @property
    def mean_diameter(self) -> float:
        """Number-mean diameter E[d] (m) of disks drawn from the curve.

        For t = d^-2 uniform on [t_lo, t_hi], E[d] = 2 / (1/d_k + 1/d_{k+1}) on segment k.
        """
        t_hi, t_lo, w = self._segments()
        return float(np.sum(w * 2.0 / (np.sqrt(t_hi) + np.sqrt(t_lo))))

    def sample(self, n: int, rng=None, stratified: bool = True) -> np.ndarray:
        """Draw ``n`` disk diameters (m) whose area-weighted distribution follows the sieve curve.

        Parameters
        ----------
        n : int, >= 1
        rng : numpy.random.Generator or int seed
        stratified : bool
            Use one uniform in each of the n strata [i/n, (i+1)/n) of the number distribution
            (default); otherwise i.i.d. uniforms. The result is randomly permuted either way.

        Returns
        -------
        (n,) float64, unordered.
        """
        n = as_int(n, "n", minimum=1)
        rng = np.random.default_rng(rng)
        u = rng.random(n)
        if stratified:
            u = (np.arange(n) + u) / n
        t_hi, t_lo, w = self._segments()
        cum = np.concatenate([[0.0], np.cumsum(w)])
        cum[-1] = 1.0
        k = np.clip(np.searchsorted(cum, u, side="right") - 1, 0, w.size - 1)
        # skip empty segments (flat parts of the curve) that searchsorted may land on at a boundary
        f = np.clip((u - cum[k]) / np.where(w[k] > 0, w[k], 1.0), 0.0, 1.0)
        t = t_hi[k] - f * (t_hi[k] - t_lo[k])
        d = t**-0.5
        return rng.permutation(d)

    # -- scaling ----------------------------------------------------------------------------
    def scaled_by(self, factor: float) -> GrainSizeDistribution:
        """The same grading with every diameter multiplied by ``factor`` (> 0)."""
        factor = as_positive_float(factor, "factor")
        return GrainSizeDistribution(self.diameters * factor, self.passing, name=self.name, source=self.source)

    def scaled(self, mean_diameter: float) -> GrainSizeDistribution:
        """The same grading scaled so that its number-mean diameter is ``mean_diameter`` (m)."""
        mean_diameter = as_positive_float(mean_diameter, "mean_diameter")
        return self.scaled_by(mean_diameter / self.mean_diameter)

    def summary(self) -> dict:
        """D10, D50, D60, D90, Cu, d_min, d_max, mean diameter (m; Cu dimensionless)."""
        return {
            "name": self.name,
            "d10": self.d10,
            "d50": self.d50,
            "d60": self.d60,
            "d90": self.d90,
            "cu": self.cu,
            "d_min": self.d_min,
            "d_max": self.d_max,
            "mean_diameter": self.mean_diameter,
        }

    def __repr__(self) -> str:
        return (
            f"GrainSizeDistribution({self.name!r}, D10={self.d10 * 1e3:.4g} mm, D50={self.d50 * 1e3:.4g} mm, "
            f"D60={self.d60 * 1e3:.4g} mm, Cu={self.cu:.3g}, {self.d_min * 1e3:.4g}-{self.d_max * 1e3:.4g} mm)"
        )


def distribution_names() -> tuple[str, ...]:
    """Names of the shipped sieve curves (files gransim/generation/data/<name>.csv)."""
    root = resources.files(__package__).joinpath(_DATA)
    return tuple(sorted(p.name[:-4] for p in root.iterdir() if p.name.endswith(".csv")))


@functools.cache
def _load_named(name: str) -> GrainSizeDistribution:
    text = resources.files(__package__).joinpath(_DATA, f"{name}.csv").read_text()
    return GrainSizeDistribution._parse(text, name, 1e-3, f"{name}.csv")


def get_distribution(name) -> GrainSizeDistribution:
    """A shipped grain size distribution by name (or a path to a CSV sieve curve in mm).

    Shipped curves (sources in their CSV headers, gransim/generation/data/):

    * ``quartz-sand``: a uniform fine-to-medium quartz beach-sand grading, D10 = 0.25, D50 = 0.34,
      D60 = 0.36, D90 = 0.47 mm, standing in for Fig. 2 of Meier, Steinmann & Kuhl, whose data
      are lost. The points were chosen to reproduce these characteristic diameters; they are not
      a measured curve.
    * ``kuhn-1002``: Kuhn (1999), section 4: diameters from 0.45 to 1.4 D50, Cu = D60/D10 = 1.7;
      the curve is derived from exactly these constraints (D10 = 0.65 D50, D60 = 1.105 D50), with
      D50 = 1 mm chosen (the paper gives no absolute size).

    A :class:`GrainSizeDistribution` passed in is returned unchanged. Raises :class:`InputError`
    naming the known distributions for an unknown name.
    """
    if isinstance(name, GrainSizeDistribution):
        return name
    if not isinstance(name, str):
        raise InputError(f"distribution: expected a name or a GrainSizeDistribution, got {type(name).__name__}")
    known = distribution_names()
    if name in known:
        return _load_named(name)
    if name.endswith(".csv") and Path(name).is_file():
        return GrainSizeDistribution.from_csv(name)
    raise InputError(
        f"unknown distribution {name!r}; choose one of: {', '.join(known)} (or give a path to a CSV sieve curve in mm)"
    )
