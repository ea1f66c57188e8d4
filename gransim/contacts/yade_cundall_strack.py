"""YADE 2023.02a's sphere-sphere contact in the plane, in YADE's own arithmetic: the geometry of
``Ig2_Sphere_Sphere_ScGeom`` (with ``avoidGranularRatcheting=False``), the shear increment of
``ScGeom::precompute``, and Cundall and Strack's elastic-frictional law
``Law2_ScGeom_FrictPhys_CundallStrack`` (Cundall & Strack, "A discrete numerical model for granular
assemblies", Geotechnique 29, 1979: F_n = k_n delta n, incremental F_s with the Coulomb cap
|F_s| <= mu |F_n|), with the stiffnesses of ``Ip2_FrictMat_FrictMat_FrictPhys`` given by
``MatchMaker(algo='val')`` (constant kn, ks for every pair).

:func:`scgeom_cundall_strack` evaluates one interaction of YADE's ``InteractionLoop``
(core/InteractionLoop.cpp:119-190) in the operation order of YADE's C++ source, so that the native
engine's ``yade`` arithmetic (:mod:`gransim.dem.yade_arithmetic`) reproduces YADE's numbers bit for
bit. Source lines are those of YADE 2023.02a (tag ``2023.02a`` of the mirror ``Aoxi-git/Cementor``,
docs/yade.md):

==========================================================  =====================================
operation                                                    YADE 2023.02a
==========================================================  =====================================
d = (x_2 + shift_2) - x_1, shift_2 = hSize cellDist          Ig2_Sphere_Sphere_ScGeom.cpp:28,
                                                             InteractionLoop.cpp:145
a new contact only when (r_1 + r_2)^2 - |d|^2 >= 0            Ig2_Sphere_Sphere_ScGeom.cpp:29-35
n = d / |d|, delta = (r_1 + r_2) - |d|                       Ig2_Sphere_Sphere_ScGeom.cpp:43-51
contact point c = x_1 + (r_1 - 0.5 delta) n                  Ig2_Sphere_Sphere_ScGeom.cpp:52
rotation axis n_old x n (0 for a new contact); twist         ScGeom.cpp:48-53
(dt 0.5 n.(w_1 + w_2)) n, zero in the plane
v_rel = (v_2 + w_2 x (c - x_2 - shift_2))                     ScGeom.cpp:88-91
- (v_1 + w_1 x (c - x_1)) + velGrad prevHSize cellDist
shear increment dt (v_rel - (n.v_rel) n)                     ScGeom.cpp:60-61
a contact with delta < 0 is reset (erased), no force         ElasticContactLaw.cpp:62-68
F_n = (kn delta) n                                           ElasticContactLaw.cpp:70
F_s -= F_s x (n_old x n); F_s -= F_s x twist (0 here)        ScGeom.cpp:15-23, ElasticContactLaw:72
F_s -= ks shearIncrement                                     ElasticContactLaw.cpp:73-74
cap: |F_s|^2 > |F_n|^2 tan(phi)^2 -> F_s *= sqrt(.)/|F_s|    ElasticContactLaw.cpp:75, 79-82
f = -F_n - F_s on body 1, -f on body 2                       ElasticContactLaw.cpp:108-110
torques (r_i - 0.5 delta) (n x f) on both bodies             ElasticContactLaw.cpp:111-112
==========================================================  =====================================

Why the plane arithmetic below is YADE's to the bit: YADE computes with Eigen 3-vectors whose z
components are exactly 0 here (2D disks: positions, velocities and normals in the plane, spins
along z). Every Eigen sum of three terms then has one exact zero term, so its association order
(which differs between Eigen's vectorised and scalar reductions) does not change the result; every
cross product reduces to one product or one difference of two products, written below in Eigen's
``cross`` order (``a_0 b_1 - a_1 b_0`` for the z component). A product with an exact 0 or a sum
with +-0 can change only the sign of a zero, never a non-zero value. ``pow(x, 2)`` is ``x * x``
(GCC folds ``pow(x, 2.0)`` into a multiplication; both are correctly rounded). Debian builds YADE
for baseline x86-64: its libraries (libyade.so, libpkg_dem.so, libpkg_common.so) hold no FMA
instruction (``objdump -d | grep -c vfmadd`` is 0 for each), so no ``a*b + c`` is fused; numba,
with ``fastmath=False`` (gransim/_numba.py), does not fuse either.

The law is a registered contact law (:func:`gransim.contacts.laws.register_law`), named
``cundall-strack-yade``, of the code "yade" (:class:`YadeCundallStrack`, :func:`yade_law`), which
``DEMSettings.hooke_law("yade")`` returns and ``Engine(..., flavour="yade")`` runs.

Units: m, s, kg, N. Arrays and scalars are float64.
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np

from .._numba import njit
from ..errors import InputError
from .laws import as_law_float, lightest_pair_mass, register_law

#: what :func:`scgeom_cundall_strack` reports about an interaction
NO_CONTACT = 0  # a non-real interaction whose spheres do not touch: Ig2 returns false, nothing changes
ERASED = 1  # the geometry was computed but delta < 0: the law returns false, YADE resets the interaction
FORCE = 2  # a real contact: forces and torques to add


def friction_tangent(mu: float) -> float:
    """tan(phi) of ``FrictPhys`` for a material made with ``frictionAngle = atan(mu)``: YADE stores
    ``tan(min(phi_1, phi_2))`` (pkg/dem/FrictPhys.cpp:39-41), which is not always ``mu`` to the last
    bit; ``math.tan`` and ``math.atan`` are the C library's, as YADE's ``std::tan`` (glibc)."""
    return math.tan(math.atan(float(mu)))


@njit
def spheres_touch(x1, y1, x2, y2, sx, sy, r1, r2):
    """Whether ``Ig2_Sphere_Sphere_ScGeom`` makes a geometry for a non-real interaction
    (Ig2_Sphere_Sphere_ScGeom.cpp:28-35, interactionDetectionFactor 1): pow(1 (r_1 + r_2), 2) -
    |d|^2 >= 0 with d = (x_2 + shift_2) - x_1 (m; arguments as :func:`scgeom_cundall_strack`)."""
    dx = (x2 + sx) - x1
    dy = (y2 + sy) - y1
    rs = r1 + r2
    return not (rs * rs - (dx * dx + dy * dy) < 0.0)


@njit
def scgeom_cundall_strack(
    real,
    x1,
    y1,
    x2,
    y2,
    sx,
    sy,
    r1,
    r2,
    v1x,
    v1y,
    w1,
    v2x,
    v2y,
    w2,
    svx,
    svy,
    nx_old,
    ny_old,
    fsx,
    fsy,
    kn,
    ks,
    tan_phi,
    dt,
    agr,
):
    """One interaction of YADE's interaction loop: geometry, shear increment and Cundall-Strack force.

    Parameters
    ----------
    real : bool, whether the interaction has its geometry and physics from earlier steps.
    x1, y1, x2, y2 : body centres (m), as YADE holds them (not wrapped).
    sx, sy : shift of body 2's periodic image, hSize cellDist (m).
    r1, r2 : radii (m). v1x .. w2 : velocities (m/s) and spins (rad/s) of the bodies.
    svx, svy : velocity of the image, velGrad prevHSize cellDist (m/s).
    nx_old, ny_old, fsx, fsy : the stored normal and shear force (N) of a real interaction.
    kn, ks : stiffnesses (N/m). tan_phi : :func:`friction_tangent`. dt : time step (s).
    agr : ``Ig2_Sphere_Sphere_ScGeom.avoidGranularRatcheting`` (its default True, Guo & Zhao's
        scripts): the relative velocity (v_2 - v_1) alpha + w_2 x (-r_2 n) - w_1 x (r_1 n) + alpha
        shiftVel with alpha = (r_1 + r_2)/(r_1 + r_2 - delta) (pkg/dem/ScGeom.cpp:65-87);
        False: at the contact point (ScGeom.cpp:88-91).

    Returns
    -------
    (status, nx, ny, pen, fnx, fny, fsx, fsy, fx, fy, t1, t2): ``status`` :data:`NO_CONTACT`,
    :data:`ERASED` or :data:`FORCE`; the new normal, penetration depth (m), normal and shear
    force stored by YADE (N, on body 2), the force f on body 1 (-f on body 2) and the z torques on
    bodies 1 and 2 (N m). Only meaningful entries are set for the other statuses.
    """
    # Ig2_Sphere_Sphere_ScGeom.cpp:28: normal = (se32.position + shift2) - se31.position
    dx = (x2 + sx) - x1
    dy = (y2 + sy) - y1
    sq = dx * dx + dy * dy
    if not real and not spheres_touch(x1, y1, x2, y2, sx, sy, r1, r2):  # :30
        return NO_CONTACT, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    norm = math.sqrt(sq)  # :43
    nx = dx / norm  # :44 normal /= norm
    ny = dy / norm
    pen = r1 + r2 - norm  # :51
    arm1 = r1 - 0.5 * pen
    cx = x1 + arm1 * nx  # :52 contactPoint
    cy = y1 + arm1 * ny
    # ScGeom::precompute (ScGeom.cpp:48-53): orthonormal_axis = normal.cross(currentNormal), z only;
    # 0 for a new geometry (and the new FrictPhys has a zero shear force)
    oz = nx_old * ny - ny_old * nx if real else 0.0
    if not real:
        fsx = 0.0
        fsy = 0.0
    # ScGeom::getIncidentVel, avoidGranularRatcheting false (ScGeom.cpp:88-91):
    # c1x = contactPoint - pos1, c2x = contactPoint - (pos2 + shift2), w x c = (-w c_y, w c_x)
    if agr:
        # ScGeom.cpp:84-86 (Eigen's cross with z-only spins: w x a = (-(w a_y), w a_x))
        rs = r1 + r2
        alpha = rs / (rs - pen)
        m2 = -r2
        rvx = ((v2x - v1x) * alpha + (-(w2 * (m2 * ny)))) - (-(w1 * (r1 * ny)))
        rvy = ((v2y - v1y) * alpha + w2 * (m2 * nx)) - w1 * (r1 * nx)
        rvx += alpha * svx  # :86 relativeVelocity += alpha * shiftVel
        rvy += alpha * svy
    else:
        c1x = cx - x1
        c1y = cy - y1
        c2x = cx - (x2 + sx)
        c2y = cy - (y2 + sy)
        rvx = (v2x - w2 * c2y) - (v1x - w1 * c1y)
        rvy = (v2y + w2 * c2x) - (v1y + w1 * c1x)
        rvx += svx  # :91 relativeVelocity += shiftVel
        rvy += svy
    # ScGeom.cpp:60: relativeVelocity - normal.dot(relativeVelocity) * normal
    dot = nx * rvx + ny * rvy
    rvx = rvx - dot * nx
    rvy = rvy - dot * ny
    six = rvx * dt  # :61 shearInc
    siy = rvy * dt
    if pen < 0.0:  # ElasticContactLaw.cpp:62-68: return false, the interaction is reset
        return ERASED, nx, ny, pen, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    # ElasticContactLaw.cpp:70: kn * max(un, 0) * normal, scalar product first
    kd = kn * pen
    fnx = kd * nx
    fny = kd * ny
    # ScGeom::rotate (ScGeom.cpp:18): shearForce -= shearForce.cross(orthonormal_axis); with the axis
    # along z, shearForce x axis = (f_y o_z - 0, 0 - f_x o_z); the twist term (:19) is 0 x f = 0
    # (Eigen evaluates the cross product into a temporary: both components use the old force)
    fsx, fsy = fsx - fsy * oz, fsy + fsx * oz
    # :74 shearForce -= ks * shearDisp
    fsx = fsx - ks * six
    fsy = fsy - ks * siy
    # :75 maxFs = normalForce.squaredNorm() * pow(tan, 2)
    max_fs = (fnx * fnx + fny * fny) * (tan_phi * tan_phi)
    fs2 = fsx * fsx + fsy * fsy
    if fs2 > max_fs:  # :79-82
        ratio = math.sqrt(max_fs) / math.sqrt(fs2)
        fsx *= ratio
        fsy *= ratio
    # :108 force = -normalForce - shearForce (on body 1); :111-112 torques
    fx = -fnx - fsx
    fy = -fny - fsy
    cross = nx * fy - ny * fx
    t1 = (r1 - 0.5 * pen) * cross
    t2 = (r2 - 0.5 * pen) * cross
    return FORCE, nx, ny, pen, fnx, fny, fsx, fsy, fx, fy, t1, t2


# ------------------------------------------------------------------ the registered law

#: YADE 2023.02a's elastic-frictional law of spheres (this module's :func:`scgeom_cundall_strack`
#: in the interaction loop of :func:`gransim.dem.yade_arithmetic._interactions`): the physics
#: ``Ip2_FrictMat_FrictMat_FrictPhys`` makes when an interaction becomes real, and the geometry
#: functor's flag.
#:
#: - ``kn``, ``ks`` (N/m): the constant stiffnesses of ``kn = MatchMaker(algo='val', val=kn)``,
#:   ``ks = MatchMaker(algo='val', val=ks)`` (the decks of reference_runs/yade/dem_script.py), used
#:   when ``young`` is 0;
#: - ``young`` (Pa), ``poisson`` (-): when ``young`` > 0, the radius-dependent stiffnesses of the
#:   material (Guo & Zhao's RVE, ``FrictMat(young, poisson)`` without MatchMaker): kn = 2 (E r_1)
#:   (E r_2)/(E r_1 + E r_2), ks the same with (E r_i) nu (pkg/dem/FrictPhys.cpp:13-44; r_i the
#:   radii, ScGeom.hpp:108), made once per interaction and kept with it;
#: - ``friction_angle`` (rad): the material's ``frictionAngle``; an interaction holds
#:   tan(min(phi_1, phi_2)) = tan(friction_angle) (FrictPhys.cpp:39-41; ``setContactFriction``
#:   sets the same, preprocessing/dem/Shop_02.cpp:867-886);
#: - ``avoid_granular_ratcheting`` (bool): ``Ig2_Sphere_Sphere_ScGeom.avoidGranularRatcheting``
#:   (True, YADE's default and Guo & Zhao's; the decks set False), the relative velocity of
#:   :func:`scgeom_cundall_strack` (``agr``).
#:
#: What of the registry this law does not use: its kernel is YADE's interaction loop over the
#: interaction container (creation order, stored normal and shear force per interaction, the
#: physics made on creation), which the yade cell of the engine runs
#: (:mod:`gransim.dem.yade_cell`), not a pair function of the list loops; so it registers no
#: ``pair`` (another arithmetic refuses it, naming the law), no history width (the container holds
#: the normal and shear force), no ``energy`` (the yade cell's ``elastic_energy`` sums
#: |F_n|^2 / 2 kn + |F_s|^2 / 2 ks over its container) and no deck lines (YADE's jobs run constant
#: scripts that read the law's parameters from their ``input.json``, reference_runs/yade).
YadeCundallStrack = namedtuple(
    "YadeCundallStrack", ["kn", "ks", "friction_angle", "young", "poisson", "avoid_granular_ratcheting"]
)

#: the law's name in the registry (:func:`gransim.contacts.laws.make_law`)
LAW_NAME = "cundall-strack-yade"


def yade_law(
    friction_angle, kn=0.0, ks=0.0, young=0.0, poisson=0.0, avoid_granular_ratcheting=True
) -> YadeCundallStrack:
    """The :class:`YadeCundallStrack` law with checked parameters: either constant stiffnesses
    (``kn`` > 0, ``ks`` >= 0, ``young`` = ``poisson`` = 0) or the material's radius-dependent ones
    (``young`` > 0, ``poisson`` >= 0, ``kn`` = ``ks`` = 0); InputError naming the law and the
    parameter otherwise. ``friction_angle`` (rad) in [0, pi/2)."""
    name = LAW_NAME
    phi = as_law_float(name, "friction_angle", friction_angle)
    if not phi < 0.5 * math.pi:
        raise InputError(f"law {name}: friction_angle must be below pi/2 rad, got {phi!r}")
    kn = as_law_float(name, "kn", kn)
    ks = as_law_float(name, "ks", ks)
    young = as_law_float(name, "young", young)
    poisson = as_law_float(name, "poisson", poisson)
    if young > 0.0 and (kn or ks):
        raise InputError(
            f"law {name}: give either kn, ks (MatchMaker's constants) or young, poisson (the material's "
            f"radius-dependent stiffnesses), got kn {kn!r}, ks {ks!r} and young {young!r}"
        )
    if young == 0.0 and (kn == 0.0 or poisson):
        raise InputError(
            f"law {name}: constant stiffnesses need kn > 0 (and no poisson), radius-dependent ones young > 0; got "
            f"kn {kn!r}, young {young!r}, poisson {poisson!r}"
        )
    if not isinstance(avoid_granular_ratcheting, (bool, np.bool_)):
        raise InputError(
            f"law {name}: avoid_granular_ratcheting must be True or False, got {avoid_granular_ratcheting!r}"
        )
    return YadeCundallStrack(kn, ks, phi, young, poisson, bool(avoid_granular_ratcheting))


def yade_timescale(law, packing, overlap=0.0):
    """(contact time, damping ratio 0) of the two lightest disks of ``packing`` (m_eff = m_1 m_2
    /(m_1 + m_2)) for the law: pi sqrt(m_eff / k) (s), k = max(kn, ks) of the constant
    stiffnesses, or of the radius-dependent ones of those two disks (2 E r_1 r_2 / (r_1 + r_2),
    times max(1, poisson)). The law is undamped (Cundall's non-viscous damping is the
    integrator's, NewtonIntegrator.damping, not the law's): damping ratio 0."""
    meff = lightest_pair_mass(packing)
    if law.young > 0.0:
        r = np.sort(np.asarray(packing.radii, float))[:2]
        kn = 2.0 * law.young * r[0] * r[1] / (r[0] + r[1])
        k = kn * max(1.0, law.poisson)
    else:
        k = max(law.kn, law.ks)
    return float(np.pi * np.sqrt(meff / k)), 0.0


register_law(
    YadeCundallStrack,
    None,
    0,
    name=LAW_NAME,
    code="yade",
    required=("friction_angle",),
    optional={"kn": 0.0, "ks": 0.0, "young": 0.0, "poisson": 0.0, "avoid_granular_ratcheting": True},
    build=lambda **p: yade_law(**p),
    description="YADE Ip2_FrictMat_FrictMat_FrictPhys + Law2_ScGeom_FrictPhys_CundallStrack",
    timescale=yade_timescale,
)


__all__ = [
    "ERASED",
    "FORCE",
    "LAW_NAME",
    "NO_CONTACT",
    "YadeCundallStrack",
    "friction_tangent",
    "scgeom_cundall_strack",
    "spheres_touch",
    "yade_law",
    "yade_timescale",
]
