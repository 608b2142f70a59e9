"""Material strength for the hydro stage: elastic-plastic deviatoric stress, yield models
(von Mises, GEO, ROCK), tensile failure and damage (docs/strength.md).

Modules: ``parameters`` (packing of resolved specs, shear table), ``yield_strength``
(Y(P, T, D)), ``elastic`` (Jaumann update, radial return), ``damage`` (ROCK failure strain),
``flaws`` (Weibull flaws of a body per cell), ``fracture`` (Grady-Kipp damage rate),
``update`` (per-cell stress kernel), ``divergence`` (conservative stress fluxes), ``model``
(:class:`MaterialStrength`, the per-step driver the Simulation calls).
"""

from impactpipe.hydro.strength.model import MaterialStrength
from impactpipe.hydro.strength.parameters import StrengthArrays, pack_strength

__all__ = ["MaterialStrength", "StrengthArrays", "pack_strength"]
