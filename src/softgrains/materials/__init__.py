"""Constitutive laws: first Piola–Kirchhoff stress, its tangent dP/dF and strain energy.

Every law is a set of small ``@njit`` functions of one point's deformation gradient F (d×d)
and its Lamé parameters, so they compile for the CPU kernels now and for CUDA later. 2D is
plane strain (ALGORITHM.md §3). :func:`law_code` maps a case-file law name to the integer
the kernels dispatch on.
"""

from softgrains.materials.dispatch import (
    LAW_CODES,
    cauchy_stress,
    lame_parameters,
    law_code,
    pk1_and_tangent,
    strain_energy,
)

__all__ = [
    "LAW_CODES",
    "cauchy_stress",
    "lame_parameters",
    "law_code",
    "pk1_and_tangent",
    "strain_energy",
]
