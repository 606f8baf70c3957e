"""BioTac geometry and the analytic weighted-normals force relation (Su et al. 2015).

Finger frame (mm), fixed to the rigid core: ``x`` along the finger towards the tip,
``z`` out of the pad (away from the fingernail), ``y = z × x`` across the finger. A
force ``F`` is the force the fingertip applies to the contact surface, so pressing the
pad on a plate gives ``Fz > 0`` (the grip force ``Fz`` of Su et al. 2015, Sec. IV-D).

Core shape (an approximation, not SynTouch's CAD): a cylinder of radius
:data:`CORE_RADIUS_MM` along ``x`` from ``x = 0`` to :data:`CYLINDER_LENGTH_MM`, capped
by a hemisphere of the same radius. A point on it is named by ``(s, phi)``: ``s`` the
arc length (mm) from the base along the surface meridian (``s <= L`` on the cylinder,
``s > L`` over the cap towards the apex), ``phi`` the azimuth about ``x`` from the pad
(``+z``, ``phi = 0``) towards ``+y``.

Electrode layout (approximation of the BioTac's published layout, which has six
electrodes down each side of the pad, four on the tip and three along the pad's centre):
three rings of five electrodes on the pad side of the cylinder at ``s = 3, 7.5, 12`` mm
and ``phi = +60, +25, 0, -25, -60`` deg, plus four on the cap. ``e1..e6`` run down the
``+y`` side (pairs at 60 and 25 deg, base to tip), ``e11..e16`` are their mirror images
(``y -> -y``), ``e17..e19`` lie on the centre line, ``e7``/``e8`` flank the tip at
``phi = +-40`` deg, ``e9`` is on the pad side of the tip and ``e10`` near the apex.
:data:`MIRROR` maps each electrode to its mirror image across the ``x-z`` plane.

Weighted-normals force estimate (Su et al. 2015, Sec. IV-A, after Wettels et al.)::

    F = sum_i (Sx E_i Nx_i, Sy E_i Ny_i, Sz E_i Nz_i)

with ``E_i`` the impedance change of electrode ``i``, ``N_i`` its unit normal and
``S`` three scales fitted by linear regression against a force plate.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

ArrayLike = npt.ArrayLike
FloatArray = npt.NDArray[np.float64]

#: Radius of the core's cylinder and hemispherical cap (mm); an approximation.
CORE_RADIUS_MM = 6.0
#: Length of the cylindrical part of the core (mm); an approximation.
CYLINDER_LENGTH_MM = 15.0
#: Channel names of the 19 electrode impedances.
ELECTRODE_NAMES: tuple[str, ...] = tuple(f"e{i}" for i in range(1, 20))
N_ELECTRODES = 19


def _cap_s(polar_deg: float) -> float:
    """Arc length ``s`` (mm) of a cap point ``polar_deg`` from the apex (+x)."""
    return CYLINDER_LENGTH_MM + CORE_RADIUS_MM * np.deg2rad(90.0 - polar_deg)


# (s mm, phi deg) of e1..e19, in channel order.
_LAYOUT_S_PHI: tuple[tuple[float, float], ...] = (
    (3.0, 60.0),  # e1
    (3.0, 25.0),  # e2
    (7.5, 60.0),  # e3
    (7.5, 25.0),  # e4
    (12.0, 60.0),  # e5
    (12.0, 25.0),  # e6
    (_cap_s(50.0), 40.0),  # e7
    (_cap_s(50.0), -40.0),  # e8
    (_cap_s(60.0), 0.0),  # e9
    (_cap_s(20.0), 0.0),  # e10
    (3.0, -60.0),  # e11
    (3.0, -25.0),  # e12
    (7.5, -60.0),  # e13
    (7.5, -25.0),  # e14
    (12.0, -60.0),  # e15
    (12.0, -25.0),  # e16
    (3.0, 0.0),  # e17
    (7.5, 0.0),  # e18
    (12.0, 0.0),  # e19
)

#: Index of each electrode's mirror image across the x-z plane (y -> -y).
MIRROR: npt.NDArray[np.intp] = np.array(
    [10, 11, 12, 13, 14, 15, 7, 6, 8, 9, 0, 1, 2, 3, 4, 5, 16, 17, 18], dtype=np.intp
)


def surface_point(s_mm: ArrayLike, phi_rad: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Point (mm) and outward unit normal of the core surface at ``(s, phi)``.

    Parameters
    ----------
    s_mm : array-like
        Arc length from the base along the meridian (mm); values past the cap's apex
        are clipped to the apex.
    phi_rad : array-like
        Azimuth about ``x`` from the pad (``+z``) towards ``+y`` (rad). Broadcast
        with ``s_mm``.

    Returns
    -------
    points, normals : ndarray, shape (..., 3)
    """
    s, phi = np.broadcast_arrays(
        np.asarray(s_mm, dtype=np.float64), np.asarray(phi_rad, dtype=np.float64)
    )
    over = np.clip(s - CYLINDER_LENGTH_MM, 0.0, 0.5 * np.pi * CORE_RADIUS_MM)
    polar = 0.5 * np.pi - over / CORE_RADIUS_MM  # angle from +x; pi/2 on the cylinder
    normals = np.stack(
        [np.cos(polar), np.sin(polar) * np.sin(phi), np.sin(polar) * np.cos(phi)],
        axis=-1,
    )
    normals[..., 0] = np.where(over > 0.0, normals[..., 0], 0.0)  # exact 0 on cylinder
    centre = np.zeros((*s.shape, 3))
    centre[..., 0] = np.minimum(s, CYLINDER_LENGTH_MM)
    return centre + CORE_RADIUS_MM * normals, normals


def _electrode_geometry() -> tuple[FloatArray, FloatArray]:
    s, phi = np.array(_LAYOUT_S_PHI).T
    points, normals = surface_point(s, np.deg2rad(phi))
    points.setflags(write=False)
    normals.setflags(write=False)
    return points, normals


#: Electrode centres (mm, finger frame), shape (19, 3); see the module docstring.
#: Electrode outward unit normals, shape (19, 3).
ELECTRODE_POSITIONS_MM, ELECTRODE_NORMALS = _electrode_geometry()


def weighted_normals_features(
    electrodes: ArrayLike, normals: ArrayLike = ELECTRODE_NORMALS
) -> FloatArray:
    """``sum_i E_i N_i`` per axis: the three regressors of the weighted-normals method.

    Parameters
    ----------
    electrodes : array-like, shape (..., 19)
        Impedance changes ``E_i`` (counts relative to the unloaded baseline).
    normals : array-like, shape (19, 3)
        Electrode unit normals.

    Returns
    -------
    ndarray, shape (..., 3)
        ``(sum E_i Nx_i, sum E_i Ny_i, sum E_i Nz_i)``.
    """
    return np.asarray(electrodes, dtype=np.float64) @ np.asarray(normals, np.float64)


def weighted_normals_force(
    electrodes: ArrayLike, scales: ArrayLike, normals: ArrayLike = ELECTRODE_NORMALS
) -> FloatArray:
    """Force (N) by Su et al. 2015, Sec. IV-A: ``F_k = S_k sum_i E_i N_k,i``.

    Parameters
    ----------
    electrodes : array-like, shape (..., 19)
        Impedance changes ``E_i`` (counts).
    scales : array-like, shape (3,)
        ``(Sx, Sy, Sz)`` in N per count.
    normals : array-like, shape (19, 3)
        Electrode unit normals.
    """
    return weighted_normals_features(electrodes, normals) * np.asarray(
        scales, dtype=np.float64
    )


def linear_drive_matrix(
    gain_counts_per_N: ArrayLike, normals: ArrayLike = ELECTRODE_NORMALS
) -> FloatArray:
    """Matrix ``A`` (19 x 3) of a linear electrode response ``E = A F`` that obeys
    the weighted-normals relation exactly.

    ``A = N (N^T N)^-1 D``: each electrode responds to the force component along one
    fixed direction, ``E_i = N_i . (N^T N)^-1 D F``, the minimum-norm pattern for which
    ``N^T E = D F``, so ``F = S * sum_i E_i N_i`` with ``S = 1 / diag(D)``. ``D`` is
    chosen so that the most responsive electrode changes by ``gain_counts_per_N[k]``
    counts per newton along axis ``k``.

    Parameters
    ----------
    gain_counts_per_N : array-like, shape (3,)
        Largest electrode sensitivity per axis (counts/N), each > 0.
    normals : array-like, shape (19, 3)
        Electrode unit normals.
    """
    n = np.asarray(normals, dtype=np.float64)
    gain = np.broadcast_to(np.asarray(gain_counts_per_N, dtype=np.float64), (3,))
    base = n @ np.linalg.inv(n.T @ n)
    return base * (gain / np.abs(base).max(axis=0))


def weighted_normals_scales(
    drive: ArrayLike, normals: ArrayLike = ELECTRODE_NORMALS
) -> FloatArray:
    """Exact ``(Sx, Sy, Sz)`` (N/count) for a response ``E = A F`` built by
    :func:`linear_drive_matrix` (``S_k = 1 / (N^T A)_kk``)."""
    nta = np.asarray(normals, dtype=np.float64).T @ np.asarray(drive, np.float64)
    return 1.0 / np.diag(nta)


def tangent_frame(normals: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Two unit tangents ``(t1, t2)`` of the surface at outward normals ``n``.

    ``t1`` runs along the meridian towards the tip (``x`` projected onto the tangent
    plane; ``-z``, over the apex, where ``n = +x``); ``t2 = n × t1`` (``+y`` on the
    pad's centre line).
    """
    n = np.asarray(normals, dtype=np.float64)
    ex = np.zeros_like(n)
    ex[..., 0] = 1.0
    t1 = ex - n[..., :1] * n
    norm = np.linalg.norm(t1, axis=-1, keepdims=True)
    apex = np.zeros_like(n)
    apex[..., 2] = -1.0
    t1 = np.where(norm > 1e-9, t1 / np.maximum(norm, 1e-12), apex)
    return t1, np.cross(n, t1)


def cone_directions(
    axis: ArrayLike, half_angle_rad: float, u: ArrayLike, v: ArrayLike
) -> FloatArray:
    """Unit vectors uniform in solid angle within ``half_angle_rad`` of ``axis``.

    ``u, v`` in [0, 1) (e.g. uniform draws) set ``cos(theta) = 1 - u (1 - cos a)`` and
    the azimuth ``2 pi v`` about the axis.
    """
    n = np.asarray(axis, dtype=np.float64)
    t1, t2 = tangent_frame(n)
    cos_t = 1.0 - np.asarray(u, np.float64) * (1.0 - np.cos(half_angle_rad))
    sin_t = np.sqrt(np.clip(1.0 - cos_t**2, 0.0, None))
    psi = 2.0 * np.pi * np.asarray(v, np.float64)
    return (
        cos_t[..., None] * n
        + (sin_t * np.cos(psi))[..., None] * t1
        + (sin_t * np.sin(psi))[..., None] * t2
    )


def neighbour_kernel(
    length_mm: float, positions: ArrayLike = ELECTRODE_POSITIONS_MM
) -> FloatArray:
    """Gaussian neighbour weights ``K_ij = exp(-d_ij^2 / (2 l^2))``, ``K_ii = 0``.

    Parameters
    ----------
    length_mm : float
        Coupling length ``l`` (mm), > 0.
    positions : array-like, shape (19, 3)
        Electrode centres (mm).
    """
    p = np.asarray(positions, dtype=np.float64)
    d2 = ((p[:, None, :] - p[None, :, :]) ** 2).sum(axis=-1)
    k = np.exp(-d2 / (2.0 * float(length_mm) ** 2))
    np.fill_diagonal(k, 0.0)
    return k


def proximity_weights(
    contact_mm: ArrayLike,
    width_mm: float,
    positions: ArrayLike = ELECTRODE_POSITIONS_MM,
) -> FloatArray:
    """``w_i = exp(-|p_i - c|^2 / (2 w^2))`` of each electrode to contact points ``c``.

    Parameters
    ----------
    contact_mm : array-like, shape (..., 3)
        Contact points (mm).
    width_mm : float
        Gaussian width ``w`` (mm), > 0.

    Returns
    -------
    ndarray, shape (..., 19)
    """
    c = np.asarray(contact_mm, dtype=np.float64)[..., None, :]
    d2 = ((np.asarray(positions, np.float64) - c) ** 2).sum(axis=-1)
    return np.exp(-d2 / (2.0 * float(width_mm) ** 2))
