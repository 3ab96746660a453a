"""A synthetic skin displacement set (Sneddon-like flat-punch dent, slope-dependent harmonic 1)
for the deformation tests: smooth in position and depth, with the FE's footprint offset."""
import numpy as np

from haptic_anfis.tissue.displacement import RHO_OVER_A, DisplacementSet

A = 0.008
FP = 0.0076  # meshed footprint outline inside the probe radius (as the FE's edge offset)
DEPTHS = np.array([0.002, 0.005, 0.008, 0.012, 0.016])


def synthetic(spacing=0.006, radius=0.03) -> DisplacementSet:
    """A Sneddon-like dent (flat punch profile) with a slope-dependent harmonic 1: smooth in
    position, so an interpolant must reproduce it closely."""
    g = np.arange(-radius, radius + 1e-9, spacing)
    yy, zz = np.meshgrid(g, g, indexing='ij')
    keep = np.hypot(yy, zz) <= radius + 1e-9
    yz = np.column_stack([yy[keep], zz[keep]])
    P, rho = len(yz), RHO_OVER_A * A
    coeffs = np.zeros((P, len(DEPTHS), len(rho), 5, 3))
    for i, (y, z) in enumerate(yz):
        for j, d in enumerate(DEPTHS):
            s = 1.0 + 0.5 * d / DEPTHS[-1]  # the shape widens with depth
            p = np.where(rho <= FP, 1.0, 2 / np.pi * np.arcsin(np.clip(FP * s / np.maximum(
                rho, FP * s), 0, 1)))
            coeffs[i, j, :, 0, 0] = d * p
            ramp = np.clip((rho - FP) / A, 0, 1)  # lateral parts start at 0 on the bonded face
            coeffs[i, j, :, 0, 1] = -0.15 * d * p * ramp
            coeffs[i, j, :, 1, 0] = d * (y / 0.05) * 0.2 * p * ramp
    x = 0.045 * np.sqrt(1 - (yz[:, 0] / 0.07) ** 2 - (yz[:, 1] / 0.07) ** 2)
    return DisplacementSet(point=np.arange(P), surface_point=np.column_stack([x, yz]),
                           direction=np.tile([-1.0, 0, 0], (P, 1)), depths=DEPTHS, rho=rho,
                           coeffs=coeffs, truncation_rms=np.zeros((P, len(DEPTHS))),
                           meta={'probe_radius_m': A, 'footprint_radius_m': FP,
                                 'dataset_sha256': 'synthetic'})
