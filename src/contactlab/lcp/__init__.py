"""Solvers for contact problems with hard constraints (SPEC C6–C9, F4, F4a, F4b).

* :func:`solve_lcp` — the LCP ``w = B λ − c ≥ 0, λ ≥ 0, λᵀ w = 0`` by projected Gauss-Seidel
  (``pgs``, C7), multi-color parallel Gauss-Seidel (``redblack``, C8), block red-black
  Gauss-Seidel (``redblack_blocks``), projected Jacobi (``jacobi``) or Lemke's pivoting
  (``lemke``, exact, any square B);
* :func:`color_rows`, :func:`color_contacts` — the coloring used by ``redblack``
  (``coloring.level_blocks``: the blocks of ``redblack_blocks``);
* :func:`solve_friction_contact` — the 3D Coulomb friction problem in FCLIB local form by
  non-smooth Gauss-Seidel (``nsgs``, F4a), normal/friction alternation (``staggered``, F4b),
  accelerated projected gradient (``apgd``) or semi-smooth Newton on the Alart–Curnier function
  (``newton``, :mod:`contactlab.lcp.newton`);
  :func:`natural_map_error` — its error measure.

Reading FCLIB HDF5 and Siconos ``.dat`` friction problems is a file's business:
:func:`contactlab.fclib.read_problem`.

See ``docs/lcp.md``.
"""

from .coloring import color_contacts, color_rows, coloring_is_valid
from .friction import FrictionResult, natural_map_error, solve_friction_contact
from .solve import LCP_METHODS, LCPResult, solve_lcp

__all__ = [
    "LCPResult",
    "LCP_METHODS",
    "solve_lcp",
    "color_rows",
    "color_contacts",
    "coloring_is_valid",
    "FrictionResult",
    "solve_friction_contact",
    "natural_map_error",
]
